"""``nnfmu demo [--out DIR]``: the main job on built-in defaults (a few minutes on 2 cores).

Generates valve data, trains a parallel and a series-parallel GRU at equal
budgets, exports both as FMUs, builds the linear and physics FMUs,
co-simulates all four in fmpy and prints the table. Re-running skips what is done.
"""

from __future__ import annotations

import argparse

from nnfmu.cli._text import description


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("demo", help="the main job in minutes: valve data, parallel vs series-parallel GRU, "
                                    "linear and physics baselines, all as FMUs scored in fmpy",
                       description=description(__doc__))
    p.add_argument("-o", "--out", default="demo-output",
                   help="output folder (default demo-output; re-use it to resume)")
    p.add_argument("--seed", type=int, default=0, help="seeds the data and the training (default 0)")
    p.add_argument("--quiet", action="store_true", help="no progress bars")
    p.set_defaults(func=_run)


def _run(args: argparse.Namespace) -> int:
    from pathlib import Path

    from nnfmu.cli._outputs import check_writable
    from nnfmu.study import run_demo

    check_writable(Path(args.out) / "results.md")  # a file at --out is named as such, before the first cell
    run_demo(args.out, seed=args.seed, progress=not args.quiet)
    return 0
