"""What one iteration of ``nnfmu fit`` costs on a dataset, measured on a few windows and scaled to the train split.

The grey-box fit (:mod:`nnfmu.greybox`) evaluates, per iteration, the residuals of every training window and
their Jacobian (forward sensitivities carried along the RK4 sub-steps, one column per free parameter and
initial state). Both scale with the number of training samples; this script times them on ``--windows``
windows of ``--window`` samples (process CPU time, one BLAS thread) and prints the figures per sample and for
the whole training split, so that a fit that cannot finish is known before it starts::

    python benchmarks/greybox_cost.py arm --data robot --window 20 --windows 2

Not part of the tests.
"""

from __future__ import annotations

import argparse
import os
import sys
import time

os.environ.setdefault("OMP_NUM_THREADS", "1")

import numpy as np  # noqa: E402


def main(argv=None) -> int:
    from nnfmu.data import load_dataset
    from nnfmu.greybox.problem import build_problem, cut_windows, theta_scales
    from nnfmu.greybox.setup import choose_unknowns
    from nnfmu.physics.registry import resolve_physics

    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("physics", help="a registered model (valve, arm, slider) or FILE.py:NAME")
    p.add_argument("--data", required=True, help="dataset folder")
    p.add_argument("--window", type=int, default=20, help="samples per timed window (default 20)")
    p.add_argument("--windows", type=int, default=2, help="windows timed (default 2)")
    p.add_argument("--free", help="the free parameters, comma-separated (default: the model's)")
    p.add_argument("--n-sub", type=int, help="RK4 sub-steps per sample (default: the model's)")
    p.add_argument("--compile", action="store_true", help="the window Functions as compiled C (the fit's default "
                   "for large models); the build time then includes the C compiler's")
    args = p.parse_args(argv)

    ds, system = load_dataset(args.data), resolve_physics(args.physics)
    unknowns = choose_unknowns(system, free=None if args.free is None else args.free.split(","))
    windows = cut_windows(ds.train.u[:args.windows], ds.train.y[:args.windows], args.window)
    windows = type(windows)(u=windows.u[:args.windows], y=windows.y[:args.windows])
    y_std = np.std(np.concatenate(list(ds.train.y)), axis=0)
    n_sub = args.n_sub or system.n_sub
    t0 = time.perf_counter() if args.compile else time.process_time()  # the compiler runs in a child process
    problem = build_problem(system, windows, unknowns.index, system.parameter_values(),
                            theta_scales(unknowns.start, unknowns.lower, unknowns.upper), y_std, n_sub=n_sub,
                            compile=args.compile)
    z = problem.pack(unknowns.start, np.zeros((problem.n_w, problem.n_x)))
    t1 = time.process_time()
    build = (time.perf_counter() if args.compile else t1) - t0
    problem.evaluate(z)
    t2 = time.process_time()
    problem.jacobian(z)
    t3 = time.process_time()
    timed = problem.n_w * (args.window - 1)  # free-run steps timed
    total = int(np.sum(ds.train.lengths))
    per_r, per_j = (t2 - t1) / timed, (t3 - t2) / timed
    print(f"{system.name}: {len(unknowns.index)} free parameters, {problem.n_x} states, RK4 with {n_sub} sub-steps; "
          f"timed {problem.n_w} window(s) of {args.window} samples, {'compiled C' if args.compile else 'CasADi VM'} "
          f"(build {build:.1f} {'wall' if args.compile else 'CPU'} s)")
    print(f"| evaluation | CPU ms per sample | CPU s on the train split's {total} samples |\n|---|---:|---:|")
    print(f"| residuals | {1e3 * per_r:.3g} | {per_r * total:.3g} |")
    print(f"| residuals + Jacobian (one iteration) | {1e3 * (per_r + per_j):.3g} | {(per_r + per_j) * total:.3g} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
