"""Issue 11's accuracy targets, measured: parallel networks of a study budget against the linear baseline.

Trains every architecture's parallel network of ``--budget`` on ``--system`` exactly as
``nnfmu reproduce`` does (the budget's presets, seeds and keep rule, the study's data preparation),
and prints per network the validation and free-run test NRMSE (float64 torch free run, which the
FMU reproduces to 1e-9), the training's process CPU time and wall time, and whether it beats the
linear baseline and the target. Not part of the test run.

    python benchmarks/accuracy_targets.py robot --data FILE.mat --linear 0.853 --target 0.70
    python benchmarks/accuracy_targets.py slider --archs gru mlp

``--linear`` takes the linear baseline's test NRMSE; without it the baseline is identified here with
the budget's options (about a minute for the robot). Torch runs on one thread per training; ``--jobs 2``
trains a network's seeds side by side.
"""

from __future__ import annotations

import argparse
import resource
import tempfile
import time
from pathlib import Path

import torch

from nnfmu.data import load_dataset
from nnfmu.study import get_budget
from nnfmu.study.cell_work import prepare_data


def _cpu_seconds() -> float:
    """Process CPU time of this process and its finished children (seeds trained in worker processes)."""
    own, kids = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    return own.ru_utime + own.ru_stime + kids.ru_utime + kids.ru_stime


def _linear(ds, options: dict) -> float:
    from nnfmu.linear import identify_linear
    from nnfmu.metrics import nrmse

    model = identify_linear(ds, **options)
    return nrmse(list(ds.test.y), [model.simulate(u, y[0]) for u, y in zip(ds.test.u, ds.test.y)]).mean


def _train(ds, budget, arch: str, seed: int, out: Path, jobs: int):
    from nnfmu.training import train, train_seeds

    hyper = budget.hyper[arch]
    model_config = hyper.model_config(arch, ds.n_u, ds.n_y)
    train_config = hyper.train_config(strategy="parallel", epochs=budget.epochs, patience=budget.patience, seed=seed,
                                      max_minutes=budget.max_minutes)
    if budget.seeds > 1:
        r = train_seeds(ds, model_config, train_config, seeds=budget.seeds, keep=budget.keep, out=out, jobs=jobs)
        return r.valid_nrmse, r.test_nrmse, r.spread()
    r = train(ds, model_config, train_config, out=out)
    return r.best_valid_nrmse, r.test_nrmse, None


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("system", choices=["valve", "arm", "robot", "slider"])
    p.add_argument("--data", help="dataset folder or the robot's .mat file (robot: required)")
    p.add_argument("--budget", default="quick")
    p.add_argument("--archs", nargs="+", help="architectures (default: the budget's)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--linear", type=float, help="the linear baseline's test NRMSE (default: identify it here)")
    p.add_argument("--target", type=float, help="print whether each network reaches this test NRMSE")
    p.add_argument("--jobs", type=int, default=1, help="seeds trained side by side (default 1)")
    args = p.parse_args()
    torch.set_num_threads(1)
    budget = get_budget(args.system, args.budget)
    with tempfile.TemporaryDirectory(prefix="nnfmu-accuracy-") as tmp:
        data = Path(tmp) / "data"
        prepare_data(args.system, budget, args.seed, Path(args.data) if args.data else None, data, False)
        ds = load_dataset(data)
        linear = args.linear if args.linear is not None else _linear(ds, dict(budget.linear))
        print(f"{args.system}, budget {budget.name}: {budget.seeds} seed(s) per network (keep {budget.keep}), "
              f"linear baseline {linear:.4f}\n")
        print(f"{'network':<8} {'valid':>7} {'test':>7} {'seeds mean [min-max]':>24} {'CPU s':>8} {'wall s':>8}  "
              "beats linear" + ("  target" if args.target else ""))
        for arch in args.archs or budget.archs:
            cpu0, wall0 = _cpu_seconds(), time.perf_counter()
            valid, test, spread = _train(ds, budget, arch, args.seed, Path(tmp) / f"{arch}.pt", args.jobs)
            cpu, wall = _cpu_seconds() - cpu0, time.perf_counter() - wall0
            seeds = f"{spread['mean']:.4f} [{spread['min']:.4f}-{spread['max']:.4f}]" if spread else "-"
            verdicts = ("yes" if test < linear else "NO") + (
                f"  {'yes' if test <= args.target else 'NO'}" if args.target else "")
            print(f"p-{arch.upper():<6} {valid:7.4f} {test:7.4f} {seeds:>24} {cpu:8.0f} {wall:8.0f}  {verdicts}",
                  flush=True)


if __name__ == "__main__":
    main()
