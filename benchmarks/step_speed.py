"""Step speed of exported FMUs against torch eager and a hand-written C GRU (issue 4, item 5).

For each architecture (GRU first) this builds a network with hidden size 64,
2 inputs and 2 outputs and random weights (seeded), exports it with
``build_fmu`` and measures, in one run:

- the FMU's step time in C: ``benchmarks/c/fmu_step_driver.c`` dlopens the
  FMU binary and loops fmi2SetReal + fmi2DoStep(Ts) + fmi2GetReal (no Python per step);
- torch eager: a Python loop over ``model.step`` at batch 1 (float32, no grad);
  for the GRU also a bare ``nn.GRUCell`` + ``nn.Linear`` loop (no normalisation,
  no skip, no state packing): the least any eager step can cost, so the
  speed-up over torch is reported against both;
- for the GRU, ``benchmarks/c/gru_hand.c``: a plain hand-written C step of the
  same network, compiled at the FMU's flags and at ``-march=x86-64-v3``;
- the export time (code generation + compile + zip) of each FMU.

Per-step figures are the minimum over repeats of a 3500-step run. The machine
is shared, so treat them as noisy; the ratios within one run are what counts.

    python benchmarks/step_speed.py [--arch gru mlp ...] [--steps 3500] [--repeats 7] [--variants]

``--variants`` also builds the GRU FMU without the matrix-kernel patch and with
``-march=x86-64-v3``, to show what each part contributes.
"""

from __future__ import annotations

import argparse
import tempfile
import time
import zipfile
from pathlib import Path

import numpy as np
import torch

from nnfmu.export.compiler import DEFAULT_FLAGS, run_compiler
from nnfmu.export.fmu import BuildOptions, build_fmu, fmi_header_dir, platform_folder
from nnfmu.models import ModelConfig, build_model

HERE = Path(__file__).parent
ARCHS = ("gru", "mlp", "rnn", "lstm", "tcn")
META = {"name": "bench", "Ts": 0.01, "inputs": [{"name": "u1", "unit": ""}, {"name": "u2", "unit": ""}],
        "outputs": [{"name": "y1", "unit": ""}, {"name": "y2", "unit": ""}]}


def make_network(arch: str, seed: int = 0):
    torch.manual_seed(seed)
    layers = {"mlp": 2, "tcn": 3}.get(arch, 1)
    model = build_model(ModelConfig(arch=arch, n_u=2, n_y=2, hidden=64, layers=layers), dict(META, name=f"{arch}64"))
    return model.eval()


def casadi_model_of(network):
    """The network as a CasadiModel, through the exporter (issue 4, item 1)."""
    from nnfmu.export import casadi_model

    return casadi_model(network)


def torch_us_per_step(network, steps: int, repeats: int) -> float:
    u = torch.tensor([[np.sin(0.01 * k * (i + 1)) * (1 + 0.5 * i) for i in range(2)] for k in range(steps)],
                     dtype=torch.float32)
    best = np.inf
    with torch.no_grad():
        for _ in range(repeats):
            x = network.init(torch.zeros(1, 2), u[:1])
            t0 = time.perf_counter()
            for k in range(steps):
                x, _ = network.step(x, u[k:k + 1])
            best = min(best, (time.perf_counter() - t0) / steps * 1e6)
    return best


def bare_gru_us_per_step(network, steps: int, repeats: int) -> float:
    """Eager time of a plain ``nn.GRUCell`` + ``nn.Linear`` step of the same sizes (batch 1, float32)."""
    hidden = network.config.hidden
    cell, head = torch.nn.GRUCell(4, hidden), torch.nn.Linear(hidden, 2)
    xs = torch.randn(steps, 1, 4)
    best = np.inf
    with torch.no_grad():
        for _ in range(repeats):
            h = torch.zeros(1, hidden)
            t0 = time.perf_counter()
            for k in range(steps):
                h = cell(xs[k], h)
                head(h)
            best = min(best, (time.perf_counter() - t0) / steps * 1e6)
    return best


def run(command: list[str]) -> tuple[float, str]:
    import subprocess

    out = subprocess.run(command, capture_output=True, text=True, check=True).stdout.strip()
    us, y = out.split()
    return float(us.split("=")[1]), y.split("=")[1]


def compile_program(source: Path, exe: Path, flags: list[str], include: list[Path]) -> Path:
    run_compiler([*flags, *(f"-I{d}" for d in include), str(source), "-o", str(exe), "-lm", "-ldl"],
                 what=f"compiling {source.name}")
    return exe


def fmu_us_per_step(fmu: Path, driver: Path, work: Path, steps: int, repeats: int) -> tuple[float, str]:
    import fmpy

    md = fmpy.read_model_description(str(fmu))
    unzip = work / fmu.stem
    zipfile.ZipFile(fmu).extractall(unzip)
    lib = unzip / "binaries" / platform_folder(2) / f"{md.coSimulation.modelIdentifier}.so"
    vrs = {c: ",".join(str(v.valueReference) for v in md.modelVariables if v.causality == c)
           for c in ("input", "output")}
    return run([str(driver), str(lib), md.guid, repr(float(md.defaultExperiment.stepSize)), str(steps), str(repeats),
                vrs["input"], vrs["output"]])


def timed_build(model, out: Path, options: BuildOptions | None = None) -> float:
    t0 = time.perf_counter()
    build_fmu(model, out, options=options)
    return time.perf_counter() - t0


def write_gru_weights(network, path: Path) -> None:
    """gru_weights.h for gru_hand.c: the network's weights column-major, in float64."""
    sd = {k: v.detach().double().numpy() for k, v in network.state_dict().items()}
    arrays = {"W_ih": sd["rnn_layers.0.weight_ih_l0"], "W_hh": sd["rnn_layers.0.weight_hh_l0"],
              "b_ih": sd["rnn_layers.0.bias_ih_l0"], "b_hh": sd["rnn_layers.0.bias_hh_l0"],
              "W_o": sd["readout.weight"], "b_o": sd["readout.bias"], "u_mean": sd["u_mean"],
              "u_std": sd["u_std"], "y_mean": sd["y_mean"], "y_std": sd["y_std"]}
    c = network.config
    lines = [f"#define NY {c.n_y}", f"#define NU {c.n_u}", f"#define H {c.hidden}",
             f"#define SKIP_SCALE {c.skip_scale if c.skip else 0.0!r}"]
    for name, a in arrays.items():
        flat = np.asarray(a, dtype=float).reshape(a.shape[0], -1).ravel(order="F")
        lines.append(f"static const double {name}[{flat.size}] = {{{', '.join(repr(float(v)) for v in flat)}}};")
    path.write_text("\n".join(lines) + "\n")


def hand_gru(network, work: Path, steps: int, repeats: int) -> dict[str, tuple[float, str]]:
    write_gru_weights(network, work / "gru_weights.h")
    results = {}
    for label, extra in (("baseline", []), ("x86-64-v3", ["-march=x86-64-v3"])):
        exe = compile_program(HERE / "c" / "gru_hand.c", work / f"gru_hand_{label}", [*DEFAULT_FLAGS, *extra], [work])
        results[label] = run([str(exe), str(steps), str(repeats)])
    return results


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--arch", nargs="+", default=list(ARCHS), choices=ARCHS)
    parser.add_argument("--steps", type=int, default=3500)
    parser.add_argument("--repeats", type=int, default=7)
    parser.add_argument("--variants", action="store_true", help="also build the GRU without the patch / with v3")
    args = parser.parse_args(argv)
    torch.set_num_threads(1)
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        driver = compile_program(HERE / "c" / "fmu_step_driver.c", work / "driver", [*DEFAULT_FLAGS],
                                 [fmi_header_dir()])
        print(f"{'model':<22}{'export s':>9}{'FMU us':>9}{'torch us':>10}{'torch/FMU':>11}  y_final")
        for arch in args.arch:
            network = make_network(arch)
            model = casadi_model_of(network)
            variants = {"": None}
            if args.variants and arch == "gru":
                variants.update({" (no patch)": BuildOptions(speed_patch=False),
                                 " (-march=x86-64-v3)": BuildOptions(target_isa="x86-64-v3")})
            eager = torch_us_per_step(network, args.steps, max(2, args.repeats // 3))
            fmu_us = None
            for label, options in variants.items():
                fmu = work / f"{arch}{len(label)}.fmu"
                seconds = timed_build(model, fmu, options)
                us, y = fmu_us_per_step(fmu, driver, work, args.steps, args.repeats)
                fmu_us = fmu_us if label else us
                print(f"{arch + '64 FMU' + label:<22}{seconds:>9.2f}{us:>9.2f}{eager:>10.1f}{eager / us:>11.1f}  {y}")
            if arch == "gru":
                bare = bare_gru_us_per_step(network, args.steps, max(2, args.repeats // 3))
                print(f"{'gru64 torch GRUCell':<22}{'':>9}{'':>9}{bare:>10.1f}{bare / fmu_us:>11.1f}"
                      "  (bare nn.GRUCell + nn.Linear loop, the eager floor)")
                for label, (us, y) in hand_gru(network, work, args.steps, args.repeats).items():
                    print(f"{'gru64 hand C ' + label:<22}{'':>9}{us:>9.2f}{'':>10}{'':>11}  {y}"
                          f"   FMU/hand = {fmu_us / us:.2f}")


if __name__ == "__main__":
    main()
