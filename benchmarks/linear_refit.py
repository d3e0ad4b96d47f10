"""Issue 38: does refitting the linear baseline on all its data, after choosing on validation, help on validation?

``nnfmu linear`` chooses the order and the refinement's stopping point on a validation split, then (the default)
estimates the model again on the training and validation records together (:mod:`nnfmu.linear.identify`, step 6).
Whether that helps must be decided without the test split. So this script plays the whole choice one level down:
the dataset's validation split (its own, or the tail ``nnfmu train`` cuts from one record) stands in for the test,
an inner validation is carved from the training split the same way, and the model is identified with and without
the refit and scored on the outer validation. The test score of the refit model (what a user gets) is printed
beside it, for the report only. Not part of the tests.

    python benchmarks/linear_refit.py data/robot data/f16 data/valve data/slider
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

from nnfmu.data import load_dataset
from nnfmu.linear import LinearConfig, identify_linear
from nnfmu.metrics import nrmse
from nnfmu.training.plan import valid_fraction


def with_tail(ds):
    """``ds`` with a validation split as ``nnfmu train`` carves it, and the records a refit should see."""
    if ds.valid is not None:
        return ds, None
    if ds.train.n_traj == 1:
        return ds.with_validation(valid_fraction(ds)), ds.train
    return ds.with_validation(0.1), None


def score(model, split) -> float:
    return nrmse(list(split.y), [model.simulate(u, y[0]) for u, y in zip(split.u, split.y)]).mean


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("datasets", nargs="+", type=Path)
    args = p.parse_args()
    print("| dataset | order | outer validation, no refit | outer validation, refit | test, no refit | test, refit "
          "| CPU s |")
    print("|---|---:|---:|---:|---:|---:|---:|")
    for path in args.datasets:
        t0 = time.process_time()
        outer, outer_whole = with_tail(load_dataset(path))
        inner_ds = outer.replace(splits={**{k: v for k, v in outer.splits.items() if k != "valid"}})
        inner, inner_whole = with_tail(inner_ds)
        row = {}
        for refit in (False, True):
            model = identify_linear(inner, LinearConfig(refit=refit), refit_on=inner_whole)
            row[("valid", refit)] = score(model, outer.valid)
            full = identify_linear(outer, LinearConfig(refit=refit), refit_on=outer_whole)
            row[("test", refit)] = score(full, outer.test)
        print(f"| {path.name} | {full.n_x} | {row['valid', False]:.4f} | {row['valid', True]:.4f} | "
              f"{row['test', False]:.4f} | {row['test', True]:.4f} | {time.process_time() - t0:.0f} |", flush=True)


if __name__ == "__main__":
    main()
