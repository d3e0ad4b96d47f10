"""Joint, frozen or staged physics in a hybrid: which default never loses to the fit it starts from?

Two mis-specified cases, each trained three ways through ``nnfmu train --arch hybrid`` at its other defaults:

- slider: the data of benchmarks/slider_misspecified.py (Stribeck friction), the physics a viscous-only user model
  fitted by ``nnfmu fit`` (its free parameters m and d);
- valve: generated valve data (small size, true parameters; 32 training, 8 validation trajectories), the physics
  with spring stiffness +30 %, orifice conductance -30 %, no end-stop damping (benchmarks/hybrid_valve.py), the
  parameters trained being k_s and C_max.

Schedules: ``joint`` (the parameters train with the network from the start), ``frozen`` (``--train-physics none``)
and ``staged`` (``--physics-schedule staged``: frozen for half the epochs, then joint at a tenth of the learning
rate). Each run has the same epochs (``--epochs``; deterministic, so the table does not depend on the machine's
load). Scores: free-run NRMSE from each record's first output, validation and test; "start" is the hybrid with
its correction at zero, i.e. the physics it starts from. The default is chosen on validation.

    nice -n 10 .venv/bin/python benchmarks/hybrid_schedules.py [--slider-epochs 40] [--valve-epochs 10]
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from hybrid_valve import NOMINAL, WRONG  # noqa: E402
from slider_misspecified import USER_MODEL, make_data  # noqa: E402

from nnfmu.data import save_dataset  # noqa: E402
from nnfmu.metrics import nrmse  # noqa: E402
from nnfmu.models import load_model  # noqa: E402
from nnfmu.physics import generate_dataset  # noqa: E402
from nnfmu.physics.slider import slider_system  # noqa: E402
from nnfmu.training import free_run  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
SCHEDULES = {"joint": [], "frozen": ["--train-physics", "none"], "staged": ["--physics-schedule", "staged"]}


def nnfmu(args: list[str]) -> float:
    """Run ``python -m nnfmu ARGS`` (output shown); its CPU seconds."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    print("$ nnfmu " + " ".join(args), flush=True)
    subprocess.run([sys.executable, "-m", "nnfmu", *args], check=True, cwd=ROOT,
                   env={**os.environ, "PYTHONHASHSEED": "0"})
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    return (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)


def scores(model, ds) -> dict:
    out = {}
    for split in ("valid", "test"):
        traj = ds.splits[split]
        preds = free_run(model, traj, float64=True)
        finite = all(np.isfinite(p).all() for p in preds)
        out[split] = float(nrmse(list(traj.y), preds).mean) if finite else float("inf")
    return out


def run_case(name: str, ds, physics: list[str], trained: list[str], epochs: int, work: Path) -> dict:
    folder = work / name
    save_dataset(ds, folder / "data", overwrite=True)
    rows = {}
    for schedule, extra in SCHEDULES.items():
        out = folder / f"{schedule}.pt"
        options = extra if schedule == "frozen" else [*trained, *extra]
        cpu = nnfmu(["train", "--data", str(folder / "data"), "--arch", "hybrid", *physics, "--epochs", str(epochs),
                     "--quiet", "--force", "-o", str(out), *options])
        model = load_model(out)
        if "start" not in rows:  # the same hybrid with its correction at zero and the physics as given
            start = load_model(out)
            for p in start.parameters():
                p.data.zero_()
            rows["start"] = {**scores(start, ds), "cpu_s": 0.0}
        rows[schedule] = {**scores(model, ds), "cpu_s": cpu}
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--slider-epochs", type=int, default=40)
    parser.add_argument("--valve-epochs", type=int, default=10)
    parser.add_argument("--workdir", type=Path, default=None)
    args = parser.parse_args()
    work = args.workdir or Path(tempfile.mkdtemp(prefix="hybrid_schedules_"))
    work.mkdir(parents=True, exist_ok=True)
    table = {}

    slider, _ = make_data(slider_system(), 0, 0.01)
    save_dataset(slider, work / "slider_fit_data", overwrite=True)
    fit_cpu = nnfmu(["fit", USER_MODEL, "--data", str(work / "slider_fit_data"), "-o", str(work / "fit.json"),
                     "--quiet"])
    table["slider"] = run_case("slider", slider, ["--physics", str(work / "fit.json")], [], args.slider_epochs, work)
    table["slider"]["start"]["cpu_s"] = fit_cpu

    valve = generate_dataset("valve", size="small", seed=0)
    valve = valve.replace(splits={"train": valve.train.subset(range(32)), "valid": valve.train.subset(range(32, 40)),
                                  "test": valve.test})
    (work / "wrong.json").write_text(json.dumps(WRONG))
    table["valve"] = run_case("valve", valve, ["--physics", "valve", "--physics-params", str(work / "wrong.json")],
                              ["--train-physics", "k_s,C_max"], args.valve_epochs, work)

    print(f"\ntrue valve k_s = {NOMINAL.k_s:g}, C_max = {NOMINAL.C_max:g}; wrong: {WRONG}")
    print(f"{'case':<8} {'schedule':<8} {'valid':>8} {'test':>8} {'CPU s':>7}")
    for case, rows in table.items():
        for schedule, r in rows.items():
            print(f"{case:<8} {schedule:<8} {r['valid']:8.4f} {r['test']:8.4f} {r['cpu_s']:7.0f}")
    (work / "table.json").write_text(json.dumps(table, indent=1))
    print(f"models and table.json in {work}")


if __name__ == "__main__":
    main()
