"""Linear baseline on the industrial robot benchmark (KUKA KR300, Weigand et al. 2022): free-run test NRMSE.

The benchmark's own baseline is a 12-state model fitted for simulation, with
inputs offset to start at zero, simulated over the test record from a zero
initial state; it is published with NRMSE 0.82 (mean of the per-joint
RMSE / std). This script identifies the same kind of model with
:func:`nnfmu.linear.identify_linear` and prints its test NRMSE with and without
the output-error refinement, for the ``zero-offset`` rule (the benchmark's
convention) and the ``estimate`` rule (the toolkit's default).

The data are the re-cut variant in ``/work/shared/data/industrial_robot`` (60
training pieces of 605 samples, one 3630-sample test record), NOT the original
file, so the figures are near, not equal, to official ones. ``--train joined``
fits on the training pieces joined into one record, as the benchmark fits one
continuous record (the pieces are consecutive; one sample is missing at each
joint).

Usage::

    python benchmarks/linear_robot.py [--init zero-offset estimate] [--train pieces joined] [--max-evaluations 150]

Each refinement takes a few minutes on one core. BLAS threads are limited to
one unless OPENBLAS_NUM_THREADS is set: the matrices are small, and on a busy
two-core machine threading made each evaluation several times slower.
"""

from __future__ import annotations

import argparse
import os
import time

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # before numpy is imported; see the docstring

import numpy as np

from nnfmu.data import load_robot_benchmark
from nnfmu.linear import identify_linear
from nnfmu.metrics import nrmse

DEFAULT_MAT = ("/work/shared/data/industrial_robot/derived_shifted_variant_NOT_ORIGINAL/"
               "forward_identification_without_raw_data_shifted.mat")
PUBLISHED = 0.82


def test_score(model, dataset):
    """Free-run NRMSE on the test split (mean over joints of RMSE / std) and the per-joint values."""
    test = dataset.test
    result = nrmse(list(test.y), [model.simulate(u, y[0]) for u, y in zip(test.u, test.y)])
    return result.mean, result.output_mean


def run_case(dataset, init: str, max_evaluations: int, refine_x0: str) -> None:
    """Identify a 12-state model without and with refinement; print one line each."""
    for refine in (False, True):
        t0 = time.perf_counter()
        model = identify_linear(dataset, order=12, init=init, refine=refine, refine_x0=refine_x0,
                                max_evaluations=max_evaluations)
        seconds = time.perf_counter() - t0
        score, joints = test_score(model, dataset)
        extra = ""
        if refine:
            rep = model.info["refinement"]
            extra = (f"  [{rep['evaluations']} evaluations, {'kept' if rep['accepted'] else 'discarded'}, "
                     f"radius {model.info['spectral_radius']:.5f}]")
        print(f"  {'refined ' if refine else 'subspace'}  test NRMSE {score:.3f}  "
              f"(valid {model.info['nrmse_valid']:.3f}; joints {np.array2string(joints, precision=2)})"
              f"  {seconds:.0f} s{extra}", flush=True)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--mat", default=DEFAULT_MAT, help="the benchmark's .mat file")
    parser.add_argument("--init", nargs="+", default=["zero-offset", "estimate"],
                        choices=["zero-offset", "estimate"], help="initial-state rules to run")
    parser.add_argument("--train", nargs="+", default=["pieces"], choices=["pieces", "joined"],
                        help="fit on the 605-sample training pieces, and/or on them joined into one record")
    parser.add_argument("--max-evaluations", type=int, default=150, help="refinement budget")
    parser.add_argument("--refine-x0", default="rule", choices=["rule", "fit"])
    args = parser.parse_args()

    dataset = load_robot_benchmark(args.mat)
    print(f"{args.mat}\n{dataset.summary()}\ncaveat: {dataset.source.get('caveat', '-')}")
    print(f"published baseline (original file): {PUBLISHED}; timings are wall-clock on a shared machine")
    variants = {"pieces": dataset,
                "joined": dataset.replace(splits={**dataset.splits, "train": dataset.train.concatenated()})}
    for init in args.init:
        for label in args.train:
            data = variants[label]
            print(f"init '{init}', training {label} ({data.train.n_traj} trajectories), 12 states:", flush=True)
            run_case(data, init, args.max_evaluations, args.refine_x0)


if __name__ == "__main__":
    main()
