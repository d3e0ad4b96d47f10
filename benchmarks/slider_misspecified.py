"""Does the physics help? The mis-specified slider (issue 23, item 6), end to end through the CLI.

Data: the full slider (Stribeck friction; m = 1 kg, d = 2 N.s/m, F_c = 1.5 N, F_s = 2.5 N), 10 training
records of 1000 samples (10 s), 2 validation and 4 test records of 2000 samples, forces within +-6 N, 1 % of
the training output std as white measurement noise. "Beyond": the same test records with every force
multiplied by 1.3 (+-7.8 N, 30 % beyond the training range), simulated by the same full model.
The user model, examples/slider_viscous.py:slider_viscous, has only m and d (no Coulomb or Stribeck part).

Models, each made by its CLI command (CPU seconds of the command are reported):
  grey-box   nnfmu fit slider_viscous (m and d estimated by free-run simulation error)
  hybrid     nnfmu train --arch hybrid --physics fit.json (derivative correction of v, seeing v and F; m and d
             trained jointly), with the batch and patience `nnfmu train` plans from the data (2 of the 10
             records a step, patience 4000 steps) as for the networks; before nnfmu planned them for a hybrid,
             its defaults (batch 64, patience 15 epochs) made one step an epoch and it stopped after 17 steps,
             validation 0.240 against 0.124 with the plan's (4 minutes; the choice made on validation)
  gru, mlp   nnfmu train --arch gru|mlp at the defaults (their data plan), the same minutes as the hybrid
  linear     nnfmu linear (order chosen on validation, output-error refinement)
Every trained model gets the same wall-clock budget (--minutes) and an epoch cap it does not reach.
Every model is scored by its free run from each record's first measured output, over every sample (the
protocol of nnfmu evaluate): NRMSE (RMSE / std of the measurement, mean over records) and RMSE in m.
A last row fits slider_viscous on data from slider_viscous itself (same structure, m = 1, d = 2 known),
started at m = 1.6, d = 1.3: the estimates, their standard errors and the bias in standard errors.

    .venv/bin/python benchmarks/slider_misspecified.py [--minutes 5] [--workdir DIR]

The hybrid's own options go in --hybrid-args="..." (with "=": they start with dashes).
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from nnfmu.data import Dataset, Trajectories, save_dataset
from nnfmu.greybox import load_fit
from nnfmu.linear import load_linear
from nnfmu.metrics import nrmse
from nnfmu.models import StepModel, load_model
from nnfmu.physics.generate_slider import SLIDER_EXCITATION, generate_slider
from nnfmu.physics.rk4 import rk4_function
from nnfmu.physics.slider import SLIDER_F_MAX, SLIDER_TS, slider_system
from nnfmu.signals import SignalLimits, excitation
from nnfmu.training import free_run

ROOT = Path(__file__).resolve().parents[1]
NNFMU = str(Path(sys.executable).with_name("nnfmu"))
USER_MODEL = "examples/slider_viscous.py:slider_viscous"
BEYOND = 1.3
SIZES = {"train": (10, 1000, 0), "valid": (2, 2000, 2), "test": (4, 2000, 1)}  # records, samples, seed stream


def _records(system, n: int, steps: int, seed: int, split: int, scale: float = 1.0) -> Trajectories:
    """``n`` records of ``steps`` samples from rest at a random position; forces (steps, 1) in N times ``scale``."""
    step = rk4_function(system.ode, Ts=SLIDER_TS, n_sub=4, name="rk4")
    p = system.parameter_values()
    limits = (SignalLimits(u_min=-SLIDER_F_MAX, u_max=SLIDER_F_MAX, rate_max=60.0),)
    us, ys = [], []
    for i in range(n):
        rng = np.random.default_rng([seed, split, i])
        x0 = np.array([rng.uniform(-5.0, 5.0), 0.0])
        u = scale * excitation(steps, Ts=SLIDER_TS, limits=limits, config=SLIDER_EXCITATION, seed=rng)
        xs = np.asarray(step.mapaccum("sim", steps - 1)(x0, u[:-1].T, np.repeat(p[:, None], steps - 1, 1)))
        us.append(u)
        ys.append(np.hstack([x0[:, None], xs]).T[:, :1])
    return Trajectories(tuple(us), tuple(ys))


def make_data(system, seed: int, noise: float) -> tuple[Dataset, Trajectories]:
    """The dataset (train, valid, test) and the beyond-range test records, both with measurement noise."""
    template = generate_slider(size="small", seed=seed)
    splits = {k: _records(system, n, steps, seed, s) for k, (n, steps, s) in SIZES.items()}
    n, steps, s = SIZES["test"]
    beyond = _records(system, n, steps, seed, s, BEYOND)

    def dataset(splits):
        return Dataset(Ts=template.Ts, inputs=template.inputs, outputs=template.outputs, splits=splits,
                       source={"generator": "benchmarks/slider_misspecified.py", "system": system.name,
                               "seed": seed}).with_measurement_noise(noise, seed=seed + 1)

    # the noise's std is a fraction of the training output std: the same train split gives the same level
    return dataset(splits), dataset({"train": splits["train"], "test": beyond}).test


def run(args: list[str]) -> float:
    """Run an nnfmu command (stdout shown) and return its CPU seconds (user + system of the child)."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    print("$ nnfmu " + " ".join(args), flush=True)
    subprocess.run([NNFMU, *args], check=True, cwd=ROOT, env={**os.environ, "PYTHONHASHSEED": "0"})
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    return (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)


def score(model, traj: Trajectories) -> tuple[float, float]:
    """(NRMSE, RMSE in m) of the free run from each record's first output; inf if it diverged."""
    if isinstance(model, StepModel):  # a network or hybrid: records of equal length simulated as one batch
        preds = free_run(model, traj, float64=True)
    else:
        preds = [model.simulate(u, y[0]) for u, y in zip(traj.u, traj.y)]
    if not all(np.isfinite(p).all() for p in preds):
        return float("inf"), float("inf")
    result = nrmse(list(traj.y), preds)
    return float(result.mean), float(np.mean(result.rmse))


def cpu_model() -> str:
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return f"{line.split(':', 1)[1].strip()}, {os.cpu_count()} cores"
    except OSError:
        pass
    return f"{platform.processor() or platform.machine()}, {os.cpu_count()} cores"


def same_structure(work: Path, seed: int, noise: float) -> str:
    """Fit slider_viscous on its own data (m = 1, d = 2); the estimates with standard errors and bias in SE."""
    from nnfmu.physics import resolve_physics
    data, _ = make_data(resolve_physics(f"{ROOT / USER_MODEL}"), seed, noise)
    save_dataset(data, work / "same", overwrite=True)
    cpu = run(["fit", USER_MODEL, "--data", str(work / "same"), "-o", str(work / "same_fit.json"),
               "--start", "m=1.6,d=1.3", "--quiet"])
    _, report = load_fit(work / "same_fit.json")
    truth = {"m": 1.0, "d": 2.0}
    cells = [f"{p} = {r['value']:.4f} +- {r['std_error']:.2g} ({(r['value'] - truth[p]) / r['std_error']:+.1f} SE)"
             for p, r in report["parameters"].items()]
    return f"same structure (true m = 1, d = 2; {cpu:.0f} CPU s): " + "; ".join(cells)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--minutes", type=float, default=5.0, help="budget of each training, hybrid and networks "
                        "(default 5)")
    parser.add_argument("--epochs", type=int, default=10000, help="epoch cap of every training (default 10000: the "
                        "minutes bind)")
    parser.add_argument("--hybrid-args", default="", help="extra options of the hybrid training (default none: "
                        "whole records, the compiled physics backend)")
    parser.add_argument("--noise", type=float, default=0.01, help="measurement noise, fraction of the output std")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--workdir", type=Path, default=None, help="keep the data and models here (default: a temp dir)")
    args = parser.parse_args()
    work = args.workdir or Path(tempfile.mkdtemp(prefix="slider_mis_"))
    work.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    data, beyond = make_data(slider_system(), args.seed, args.noise)
    save_dataset(data, work / "data", overwrite=True)
    D = str(work / "data")
    budget = ["--epochs", str(args.epochs), "--quiet", "--force"]
    rows = {}
    cpu = run(["fit", USER_MODEL, "--data", D, "-o", str(work / "fit.json"), "--quiet"])
    system, report = load_fit(work / "fit.json")
    fitted = ", ".join(f"{p} = {r['value']:.3g} +- {r['std_error']:.2g}" for p, r in report["parameters"].items())
    rows["grey-box (" + fitted + ")"] = (system.model(expose_parameters=False), cpu)
    cpu = run(["train", "--arch", "hybrid", "--physics", str(work / "fit.json"), "--data", D,
               "-o", str(work / "hybrid.pt"), "--max-minutes", str(args.minutes), *budget, *args.hybrid_args.split()])
    rows["hybrid on the grey-box fit"] = (load_model(work / "hybrid.pt"), cpu)
    for arch in ("gru", "mlp"):
        cpu = run(["train", "--arch", arch, "--data", D, "-o", str(work / f"{arch}.pt"),
                   "--max-minutes", str(args.minutes), *budget])
        rows[arch] = (load_model(work / f"{arch}.pt"), cpu)
    cpu = run(["linear", "--data", D, "--save", str(work / "linear.json"), "--quiet"])
    rows["linear"] = (load_linear(work / "linear.json"), cpu)
    same = same_structure(work, args.seed, args.noise)

    print(f"\nmis-specified slider: {SIZES['train'][0]} training records; CPU: {cpu_model()}; "
          f"{time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}; wall {time.perf_counter() - t0:.0f} s")
    print(f"{'model':<44} {'valid':>7} {'test':>7} {'beyond':>7} {'ratio':>6} {'test RMSE':>10} {'beyond RMSE':>12} "
          f"{'ratio':>6} {'CPU s':>6}")
    table = {}
    for name, (model, cpu) in rows.items():
        (v, _), (t, tr), (b, br) = score(model, data.valid), score(model, data.test), score(model, beyond)
        table[name] = dict(valid=v, test=t, beyond=b, test_rmse=tr, beyond_rmse=br, cpu_s=cpu)
        print(f"{name:<44} {v:7.4f} {t:7.4f} {b:7.4f} {b / t:6.2f} {tr:10.4f} {br:12.4f} {br / tr:6.2f} {cpu:6.0f}")
    print(same)
    (work / "table.json").write_text(json.dumps({"rows": table, "same_structure": same, "cpu": cpu_model()}, indent=1))
    print(f"data, models and table.json in {work}")


if __name__ == "__main__":
    main()
