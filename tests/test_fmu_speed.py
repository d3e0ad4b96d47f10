"""The FMU's build profiles and precisions (docs/fmu-speed.md): what each promises against torch and CasADi.

- fast (the default): every architecture equals the float64 torch model within 1e-12 (relative to the
  output's magnitude) over 3500 steps; its binary also runs on a CPU without AVX;
- exact: the same bits as CasADi's own evaluation;
- float32: within 1e-5 of the float64 torch model, and costs less than 1e-3 free-run NRMSE on the valve
  test set against the float64 FMU;
- the weight panels are right for awkward matrix shapes, in both precisions;
- the incremental TCN predicts what the windowed TCN predicts, with one column per layer and step.
"""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import zipfile
from pathlib import Path

import casadi as ca
import fmpy
import numpy as np
import pytest
import torch
from fmpy.validation import validate_fmu
from fmu_cases import fmpy_simulate

from nnfmu.errors import ConfigError
from nnfmu.export import build_fmu, casadi_model
from nnfmu.cbuild import run_compiler
from nnfmu.export.fmu import BuildOptions, fmi_header_dir, platform_folder
from nnfmu.models import ModelConfig, build_model
from nnfmu.system import CasadiModel, SystemSpec
from builtin_networks import ARCHS

N_STEPS = 3500
NORM = {"u_mean": [100.0, 120.0], "u_std": [70.0, 60.0], "y_mean": [5e-4, 4e5], "y_std": [3e-4, 1.5e5]}
OPTIONS = {"gru": {}, "lstm": {"layers": 2}, "rnn": {"activation": "relu"}, "mlp": {"activation": "elu"},
           "tcn": {"activation": "tanh"}}
FAST, FLOAT32, EXACT = BuildOptions(), BuildOptions(precision="float32"), BuildOptions(profile="exact")
DRIVER = Path(__file__).parents[1] / "benchmarks" / "c" / "fmu_step_driver.c"


def rel_error(actual, expected) -> float:
    """Largest error relative to each output's largest magnitude."""
    return float((np.abs(actual - expected) / np.abs(expected).max(axis=0)).max())


@pytest.fixture(scope="module")
def valve_inputs(valve_small):
    return np.concatenate(valve_small.test.u)[:N_STEPS], valve_small.test.y[0][0]


@pytest.fixture(scope="module")
def networks():
    models = {}
    for arch in ARCHS:
        torch.manual_seed(1)
        models[arch] = build_model(ModelConfig(arch=arch, n_u=2, n_y=2, hidden=12, **OPTIONS[arch]))
        models[arch].set_normalisation(NORM)
    return models


@pytest.fixture(scope="module")
def fmus(networks, tmp_path_factory):
    """Every architecture as a fast float64 and a fast float32 FMU: ``{(arch, precision): path}``."""
    folder = tmp_path_factory.mktemp("speed_fmus")
    return {(arch, options.precision): build_fmu(casadi_model(net), folder / f"{arch}_{options.precision}.fmu",
                                                 options=options)
            for arch, net in networks.items() for options in (FAST, FLOAT32)}


@pytest.mark.parametrize("precision, tolerance", [("float64", 1e-12), ("float32", 1e-5)])
@pytest.mark.parametrize("arch", ARCHS)
def test_fast_fmu_of_every_architecture_equals_torch_within_the_stated_tolerance(
        networks, fmus, valve_inputs, arch, precision, tolerance):
    fmu = fmus[arch, precision]
    assert validate_fmu(str(fmu)) == []
    network = networks[arch]
    expected = network.simulate(*valve_inputs)
    got = fmpy_simulate(fmu, casadi_model(network), *valve_inputs)
    assert np.ptp(expected, axis=0).min() > 1e-3 * np.abs(expected).max(axis=0).min(), "outputs must move"
    assert rel_error(got, expected) < tolerance


def test_exact_profile_computes_the_same_bits_as_casadi(networks, valve_inputs, tmp_path):
    model = casadi_model(networks["gru"])
    fmu = build_fmu(model, tmp_path / "exact.fmu", options=EXACT)
    np.testing.assert_array_equal(fmpy_simulate(fmu, model, *valve_inputs), model.simulate(*valve_inputs))


CLANG_LIKE = """#!/bin/sh
# a compiler that says it is clang and, like clang and zig cc, rejects GCC's own flags; it compiles with gcc
if [ "$1" = "-dM" ]; then echo "#define __GNUC__ 4"; echo "#define __clang__ 1"; exit 0; fi
for a in "$@"; do
  case "$a" in -fno-tree-loop-distribute-patterns) echo "error: unknown argument: '$a'" >&2; exit 1;; esac
done
exec gcc "$@"
"""


@pytest.mark.skipif(shutil.which("gcc") is None, reason="needs gcc behind the clang-like compiler")
def test_fast_profile_builds_with_a_compiler_that_is_not_gcc(networks, fmus, valve_inputs, tmp_path):
    """The fast profile's GCC-only flag must not reach clang (or zig cc): users with CC=clang get the same FMU."""
    fake = tmp_path / "clang-like"
    fake.write_text(CLANG_LIKE)
    fake.chmod(0o755)
    model = casadi_model(networks["gru"])
    fmu = build_fmu(model, tmp_path / "clang.fmu", options=BuildOptions(compiler=str(fake)))
    got = fmpy_simulate(fmu, model, *valve_inputs)
    assert rel_error(got, fmpy_simulate(fmus["gru", "float64"], model, *valve_inputs)) < 1e-12


def test_float32_costs_less_than_1e_3_nrmse_on_the_valve_test_set(valve_small, tmp_path):
    from nnfmu.cosim import evaluate
    from nnfmu.models.base import torch_threads
    from nnfmu.training import TrainConfig, train

    data = valve_small.replace(splits={"train": valve_small.train.subset(range(8)),
                                       "valid": valve_small.train.subset([8]), "test": valve_small.test})
    with torch_threads(1):
        network = train(data, ModelConfig(arch="gru", n_u=2, n_y=2, hidden=16),
                        TrainConfig(epochs=3, batch_size=8, truncate=30, lr=1e-2)).model
    model = casadi_model(network)
    paths = [build_fmu(model, tmp_path / f"gru_{o.precision}.fmu", options=o) for o in (FAST, FLOAT32)]
    f64, f32 = (e.result.mean for e in evaluate(paths, valve_small))
    assert f64 < 1.0, "the trained network must predict the valve better than its mean"
    assert abs(f32 - f64) < 1e-3


def awkward_model() -> CasadiModel:
    """Products with 1 to 70 rows, a right factor with several columns, a weight shared by two products
    and one also used element-wise (which must stay column-major), in one MX step."""
    rng = np.random.default_rng(3)
    W = {shape: ca.DM(rng.normal(size=shape) / np.sqrt(shape[1])) for shape in
         [(70, 70), (33, 70), (5, 7), (3, 70), (1, 7), (9, 7), (8, 1)]}
    x, u = ca.MX.sym("x", 70), ca.MX.sym("u", 1)
    shared, reused = ca.MX(W[(5, 7)]), ca.MX(W[(9, 7)])  # MX: one constant in the C code, used twice
    x_next = ca.tanh(0.9 * ca.mtimes(W[(70, 70)], x) + ca.repmat(u, 70, 1))
    block = ca.mtimes(W[(33, 70)], ca.horzcat(x, x_next, 2 * x))  # ncol_y = 3
    y = ca.vertcat(ca.sum2(block), ca.mtimes(shared, x[:7]), ca.mtimes(shared, x_next[:7]),
                   ca.mtimes(W[(3, 70)], x_next), ca.mtimes(W[(1, 7)], x[7:14]),
                   ca.mtimes(reused, x[:7]) * reused[:, 0], ca.mtimes(W[(8, 1)], u))
    step = ca.Function("step", [x, u], [x_next, y], ["x", "u"], ["x_next", "y_next"])
    y0, u0 = ca.MX.sym("y0", y.shape[0]), ca.MX.sym("u0", 1)
    init = ca.Function("init", [y0, u0], [ca.sin(ca.vertcat(y0, y0)[:70])], ["y0", "u0"], ["x0"])
    return CasadiModel(init, step, SystemSpec("awkward", 0.1, ["u"], [f"y{i}" for i in range(y.shape[0])]))


@pytest.mark.parametrize("options, tolerance", [(FAST, 1e-13), (FLOAT32, 1e-5)])
def test_weight_panels_are_right_for_awkward_shapes(tmp_path, options, tolerance):
    model = awkward_model()
    fmu = build_fmu(model, tmp_path / "awkward.fmu", options=options)
    with zipfile.ZipFile(fmu) as zf:
        source = zf.read("sources/model_casadi.c").decode()
    panels = re.findall(r"nnfmu_gemv_panel\(\w+, (\d+), (\d+), \w+, (\d+)", source)
    assert sorted(panels) == sorted([("70", "70", "1"), ("33", "70", "3"), ("5", "7", "1"), ("5", "7", "1"),
                                     ("3", "70", "1")]), "the constant weights use the panel kernel"
    assert re.search(r"casadi_mtimes_dense\(\w+, 9, 7,", source), "a weight also used element-wise stays as it was"
    u = np.sin(0.3 * np.arange(60))[:, None]
    y0 = np.linspace(-1, 1, model.spec.n_y)
    assert rel_error(fmpy_simulate(fmu, model, u, y0)[1:], model.simulate(u, y0)[1:]) < tolerance


@pytest.mark.parametrize("options", [dict(), dict(kernel_size=2, layers=4), dict(layers=1),
                                     dict(layers=2, activation="relu", skip=False)])
def test_incremental_tcn_predicts_what_the_windowed_tcn_predicts(options):
    """The delay-line step (torch and FMU) against the TCN evaluated over its whole window at every step."""
    from nnfmu.models import WindowStepModel

    torch.manual_seed(2)
    model = build_model(ModelConfig(arch="tcn", n_u=2, n_y=2, hidden=6, **options)).double().eval()
    model.set_normalisation(NORM)
    u = torch.from_numpy(np.array(NORM["u_mean"]) + np.array(NORM["u_std"]) * np.random.default_rng(0).normal(
        size=(1, 200, 2)))
    y0 = torch.tensor([[6e-4, 3e5]], dtype=torch.float64)
    with torch.no_grad():
        incremental = model(u, y0)
        windowed = WindowStepModel.free_run_norm(model, model.normalise_u(u), model.normalise_y(y0))
    assert rel_error(incremental[0, 1:].numpy(), model.denormalise_y(windowed[0, 1:]).numpy()) < 1e-12


def test_tcn_step_computes_one_column_per_layer(networks):
    """The exported TCN step multiplies each layer's weights with one column, not the whole window."""
    network = networks["tcn"]
    step = casadi_model(network).step
    products = [step.instruction_MX(k) for k in range(step.n_instructions()) if step.instruction_id(k) == ca.OP_MTIMES]
    assert len(products) == network.config.layers + 1  # the convolutions and the head
    assert all(p.shape[1] == 1 for p in products)


def test_unknown_profile_or_precision_lists_the_valid_ones():
    with pytest.raises(ConfigError, match="unknown build profile 'turbo'; choose one of fast, exact"):
        BuildOptions(profile="turbo")
    with pytest.raises(ConfigError, match="unknown build precision 'float16'; choose one of float64, float32"):
        BuildOptions(precision="float16")


def test_cli_builds_float32_and_rejects_an_unknown_precision(tmp_path, capsys, networks):
    from nnfmu.export.__main__ import main as export_main
    from nnfmu.models import save_checkpoint

    ckpt = save_checkpoint(tmp_path / "gru.pt", networks["gru"])
    out = tmp_path / "gru32.fmu"
    assert export_main([str(ckpt), "-o", str(out), "--precision", "float32", "--profile", "exact"]) == 0
    with zipfile.ZipFile(out) as zf:
        source = zf.read("sources/model_casadi.c").decode()
    assert "#define casadi_real float" in source and "nnfmu_gemv_panel" not in source
    with pytest.raises(SystemExit) as info:
        export_main([str(ckpt), "-o", str(out), "--precision", "float16"])
    assert info.value.code == 2 and "invalid choice: 'float16'" in capsys.readouterr().err


def run_driver(command: list[str], fmu: Path, steps: int) -> np.ndarray:
    md = fmpy.read_model_description(str(fmu))
    folder = fmu.with_suffix("")
    zipfile.ZipFile(fmu).extractall(folder)
    lib = folder / "binaries" / platform_folder(2) / f"{md.coSimulation.modelIdentifier}.so"
    vrs = [",".join(str(v.valueReference) for v in md.modelVariables if v.causality == c) for c in ("input", "output")]
    ts = repr(float(md.defaultExperiment.stepSize))
    out = subprocess.run([*command, str(lib), md.guid, ts, str(steps), *vrs], capture_output=True, text=True,
                         check=True, timeout=300).stdout
    return np.array([float(v) for v in out.split("y_final=")[1].split(",")])


@pytest.mark.skipif(os.uname().machine != "x86_64" or not shutil.which("qemu-x86_64"),
                    reason="needs x86-64 and qemu-user (apt-get install qemu-user) to run the FMU on an emulated "
                           "CPU without AVX")
def test_fast_binary_has_avx2_fma_and_avx512_clones_and_runs_on_a_cpu_without_avx(fmus, tmp_path):
    fmu = fmus["gru", "float64"]
    driver = tmp_path / "driver"
    run_compiler(["-O2", "-std=c99", f"-I{fmi_header_dir()}", str(DRIVER), "-o", str(driver), "-lm", "-ldl"],
                 what="compiling the step driver")
    native = run_driver([str(driver)], fmu, 300)
    emulated = run_driver(["qemu-x86_64", "-cpu", "Nehalem", str(driver)], fmu, 300)  # SSE4.2, no AVX
    np.testing.assert_allclose(emulated, native, rtol=1e-12)
    if shutil.which("nm"):
        lib = next(fmu.with_suffix("").rglob("*.so"))
        symbols = subprocess.run(["nm", str(lib)], capture_output=True, text=True, check=True).stdout
        assert re.search(r"_f1\.arch_x86_64_v3\b", symbols) and re.search(r"_f1\.arch_x86_64_v4\b", symbols)
