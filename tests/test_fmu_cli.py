"""The FMU command lines: ``nnfmu physics-fmu`` and ``python -m nnfmu.export`` (= ``nnfmu export``)."""

from __future__ import annotations

import fmpy
import numpy as np
import pytest
import torch
from fmpy.validation import validate_fmu
from fmu_cases import fmpy_simulate

from nnfmu.cli import main as nnfmu_main
from nnfmu.export.__main__ import main as export_main
from nnfmu.models import ModelConfig, build_model, load_model, save_checkpoint
from nnfmu.physics.arm import ARM_TAU_LIMITS_NM

VALVE_META = {"name": "valve_net", "Ts": 4e-5,
              "inputs": [{"name": "u1", "unit": "V"}, {"name": "u2", "unit": "V"}],
              "outputs": [{"name": "s", "unit": "m"}, {"name": "p", "unit": "Pa"}]}


def rel_error(actual, expected) -> float:
    return float((np.abs(actual - expected) / np.abs(expected).max(axis=0)).max())


@pytest.mark.parametrize("system, version, n", [("valve", 3, 400), ("arm", 2, 30)])
def test_physics_fmu_validates_and_equals_the_casadi_simulation(tmp_path, capsys, system, version, n):
    from nnfmu.cli.physics_fmu import physics_system

    out = tmp_path / f"{system}.fmu"
    only_cs = ["--no-model-exchange"] if system == "arm" else []  # the arm's ODE code doubles its compile time
    assert nnfmu_main(["physics-fmu", system, "-o", str(out), "--fmi-version", str(version), *only_cs]) == 0
    interfaces = "co-simulation, model" if only_cs else "co-simulation and model exchange, model"
    assert f"wrote {out} (FMI {version}.0 {interfaces}" in capsys.readouterr().out
    assert validate_fmu(str(out)) == []
    model = physics_system(system).model()
    limits = {"valve": [(0.0, 250.0)] * 2, "arm": list(ARM_TAU_LIMITS_NM)}[system]  # the physical limits
    md = fmpy.read_model_description(str(out))
    assert [(float(v.min), float(v.max)) for v in md.modelVariables if v.causality == "input"] == limits
    t = np.arange(n)[:, None] * model.spec.Ts
    scale = {"valve": (2.5, 2.0), "arm": (0.0, 30.0)}[system]
    u = scale[0] + scale[1] * np.sin(2 * np.pi * t * np.linspace(1, 2, model.spec.n_u) / (n * model.spec.Ts) * 3)
    y0 = np.array([v.start for v in model.spec.outputs])
    expected = model.simulate(u, y0)
    assert np.ptp(expected, axis=0).max() > 0, "the inputs must move the system"
    assert rel_error(fmpy_simulate(out, model, u, y0), expected) < 1e-9


def test_physics_fmu_rejects_bad_options(capsys):
    assert nnfmu_main(["physics-fmu", "valve", "--n-sub", "0", "-o", "x.fmu"]) == 2
    assert "--n-sub must be a whole number >= 1 and <= 10000, got 0" in capsys.readouterr().err
    assert nnfmu_main(["physics-fmu", "pendulum"]) == 2
    assert "unknown physics model 'pendulum'; choose one of arm, slider, valve, or give a model file" in \
        capsys.readouterr().err


@pytest.fixture(scope="module")
def checkpoints(tmp_path_factory):
    """Small random networks of every architecture with non-trivial normalisation, saved as checkpoints."""
    folder = tmp_path_factory.mktemp("checkpoints")
    paths = {}
    for i, arch in enumerate(("gru", "lstm", "rnn", "mlp", "tcn")):
        torch.manual_seed(i)
        net = build_model(ModelConfig(arch=arch, n_u=2, n_y=2, hidden=8), dict(VALVE_META, name=f"valve_{arch}"))
        with torch.no_grad():
            net.u_mean.fill_(2.5), net.u_std.fill_(1.5)
            net.y_mean.copy_(torch.tensor([5e-4, 3e5])), net.y_std.copy_(torch.tensor([2e-4, 1e5]))
        paths[arch] = save_checkpoint(folder / f"{arch}.pt", net)
    return paths


@pytest.mark.parametrize("version", [2, 3])
@pytest.mark.parametrize("arch", ["gru", "lstm", "rnn", "mlp", "tcn"])
def test_exported_checkpoint_equals_the_torch_model(tmp_path, capsys, checkpoints, arch, version):
    out = tmp_path / f"{arch}.fmu"
    assert export_main([str(checkpoints[arch]), "-o", str(out), "--fmi-version", str(version)]) == 0
    assert validate_fmu(str(out)) == []
    inputs = [v for v in fmpy.read_model_description(str(out)).modelVariables if v.causality == "input"]
    assert [(float(v.min), float(v.max)) for v in inputs] == [(-3.5, 8.5)] * 2  # no stored range: 2.5 +- 4 x 1.5
    network = load_model(checkpoints[arch])
    from nnfmu.export import casadi_model

    model = casadi_model(network)
    rng = np.random.default_rng(0)
    n = 400  # the torch TCN free run is slow (about 3 ms per step)
    u = 2.5 + 1.5 * np.sin(np.arange(n)[:, None] * np.array([0.02, 0.031])) + 0.2 * rng.normal(size=(n, 2))
    y0 = np.array([4e-4, 2.5e5])
    assert rel_error(fmpy_simulate(out, model, u, y0), network.simulate(u, y0)) < 1e-9


def test_export_name_option_sets_the_model_identifier(tmp_path, capsys, checkpoints):
    out = tmp_path / "renamed.fmu"
    assert export_main([str(checkpoints["gru"]), "-o", str(out), "--name", "ValveGRU"]) == 0
    assert fmpy.read_model_description(str(out)).coSimulation.modelIdentifier == "ValveGRU"
    assert export_main([str(checkpoints["gru"]), "-o", str(tmp_path / "x.fmu"), "--name", "valve gru"]) == 2
    assert "--name must be an ASCII C identifier" in capsys.readouterr().err


@pytest.mark.parametrize("content, message", [
    (None, "no checkpoint file at"),
    (b"this is not a checkpoint", "not a readable torch checkpoint"),
])
def test_export_of_a_bad_checkpoint_is_one_clear_line(tmp_path, capsys, content, message):
    path = tmp_path / "model.pt"
    if content is not None:
        path.write_bytes(content)
    assert export_main([str(path), "-o", str(tmp_path / "m.fmu")]) == 2
    err = capsys.readouterr().err
    assert err.startswith("python -m nnfmu.export: error: ") and message in err and "Traceback" not in err
    assert not (tmp_path / "m.fmu").exists()
