"""Issue 38: would joining every architecture's seeds at the defaults beat the best architecture alone?

``benchmarks/defaults_table.py`` trains each architecture at its defaults and keeps every seed's checkpoint in
``WORK/DATASET/ARCH.seeds/seed-*.pt``. This script reads them back (no training) and compares, on the validation
the trainings used (carved as ``nnfmu train`` carves it):

- each architecture's kept model (``WORK/DATASET/ARCH.pt``: its best seed, or the seeds' ensemble);
- the greedy ensemble over every seed of every architecture (:func:`nnfmu.training.ensemble_select.select_ensemble`,
  best on validation first, a member joining where it lowers the validation NRMSE by 1 %, up to 4), which a
  default that trained every architecture would keep;
- every seed of every architecture averaged, with no choice at all.

The test column (free run from y0, float64 torch) is reported, not used: the rule is chosen on validation.

    python benchmarks/defaults_table.py data/robot --work W          # first: the cells and their seeds
    python benchmarks/across_archs.py data/robot --work W
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import torch

from nnfmu.data import load_dataset
from nnfmu.models import load_checkpoint, model_from_checkpoint
from nnfmu.training.ensemble_select import ensemble_score, select_ensemble
from nnfmu.training.evaluate import score


def validation(data: Path):
    """The validation trajectories ``nnfmu train --data data`` validates on (its plan's carve and join)."""
    from nnfmu.cli._train_plan import TrainRequest, make_plan
    from nnfmu.training.horizons import validation_trajectories

    plan = make_plan(TrainRequest(data=str(data), out=Path("unused.pt"), arch="gru", linear_path="off", quiet=True))
    return validation_trajectories(plan.data, plan.train_config)[0]


def compare(data: Path, work: Path) -> None:
    t0 = time.monotonic()
    valid, test = validation(data), load_dataset(data).test
    seeds = {f"{f.parent.name.removesuffix('.seeds')} {f.stem}": f for f in sorted(work.glob("*.seeds/seed-*.pt"))}
    cells = {f.stem: f for f in sorted(work.glob("*.pt")) if (work / f"{f.stem}.seeds").is_dir()}  # not a search
    if not seeds:
        raise SystemExit(f"no seed checkpoints in {work}/*.seeds: run benchmarks/defaults_table.py first")
    models = {name: model_from_checkpoint(load_checkpoint(f)).eval() for name, f in {**seeds, **cells}.items()}
    rows = []
    with torch.no_grad():
        valid_of = {name: ensemble_score([m], valid)[1] for name, m in models.items()}
        ranked = sorted(seeds, key=valid_of.get)
        selection = select_ensemble([models[n] for n in ranked], valid)
        members = [ranked[j] for j in selection.chosen]
        for name in cells:
            rows.append((f"{name} at its defaults (kept)", valid_of[name], score(models[name], test, float64=True)))
        rows.append((f"every seed, greedy on validation: {', '.join(members)}", selection.scores[-1],
                     score(selection.model, test, float64=True)))
        everything, v = ensemble_score([models[n] for n in seeds], valid)
        rows.append((f"all {len(seeds)} seeds averaged", v, score(everything, test, float64=True)))
    print(f"\n## {data.name}: {len(seeds)} seeds of {len(cells)} architectures in {work}, "
          f"{time.monotonic() - t0:.0f} s")
    print("| model | validation NRMSE | test NRMSE (reported) |")
    print("|---|---:|---:|")
    for name, v, t in rows:
        print(f"| {name} | {v:.4f} | {t:.4f} |", flush=True)


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("datasets", nargs="+", type=Path)
    p.add_argument("--work", type=Path, required=True, help="defaults_table.py's --work folder")
    args = p.parse_args()
    torch.set_num_threads(1)
    for data in args.datasets:
        compare(data, args.work / data.name)


if __name__ == "__main__":
    main()
