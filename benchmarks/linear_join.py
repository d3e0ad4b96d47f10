"""Issue 38: the linear model of a dataset of consecutive pieces (the robot), fitted on them apart or joined.

``nnfmu linear`` and the linear path of ``nnfmu train`` join each split's records end to end where the dataset
says they are consecutive pieces of one recording (``LinearConfig.join``). This identifies both ways without the
refit (which sees the validation data, so validation would no longer be unseen) and prints the validation
free-run NRMSE over the joined validation record and over its separate pieces, which decide, then the test,
which is only reported, and the CPU seconds. Not part of the tests. Name the CPU beside the figures.

    python benchmarks/linear_join.py data/robot
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np

from nnfmu.data import Trajectories, load_dataset
from nnfmu.linear import LinearConfig, identify_linear
from nnfmu.metrics import nrmse


def score(model, records: Trajectories) -> float:
    """The mean over records of the free run's NRMSE (mean over outputs), from each record's measured y0."""
    return float(np.mean([nrmse(y, model.simulate(u, y[0])).mean for u, y in zip(records.u, records.y)]))


def main(argv=None) -> int:
    data = Path((argv or sys.argv[1:])[0])
    ds = load_dataset(data)
    joined = ds.valid.concatenated()
    print("| linear model, no refit | order | valid, joined record | valid, separate pieces | test (reported) | CPU s |")
    print("|---|---:|---:|---:|---:|---:|", flush=True)
    for name, join in (("pieces apart", False), ("joined", True)):
        t0 = time.process_time()
        model = identify_linear(ds, LinearConfig(refit=False, join=join))
        cpu = time.process_time() - t0
        print(f"| {name} | {model.n_x} | {score(model, joined):.4f} | {score(model, ds.valid):.4f} | "
              f"{score(model, ds.test):.4f} | {cpu:.0f} |", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
