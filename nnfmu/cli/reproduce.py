"""``nnfmu reproduce SYSTEM --out DIR [--budget smoke|quick|paper] [--data PATH] [--tune] [--seed N]``.

Runs the paper's study as resumable cells (see :mod:`nnfmu.study.pipeline`):
data, 5 architectures x 2 strategies, every model exported to an FMU, the
linear and physics baselines, fmpy scores, ``results.md``, ``results.json``
and the figures. Running it again skips what is done and resumes an
interrupted training from its checkpoint.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from nnfmu.cli._arch import LazyChoices
from nnfmu.cli._physics_info import study_names
from nnfmu.cli._resources import add_resource_options

_DESCRIPTION = (
    "Reproduce the paper's study (parallel vs series-parallel training of MLP, RNN, LSTM, GRU and TCN) on the "
    "valve, the arm or the slider (generated data) or the industrial robot (measured data, --data). Every "
    "model, the linear "
    "baseline and the physics model are exported as FMUs and scored by co-simulation in fmpy. Budgets: smoke "
    "(minutes, numbers mean nothing), quick (well under an hour), paper (the paper's protocol, with a Ray Tune "
    "grid search; hours). Re-running with the same options skips what is done; Ctrl-C keeps the training "
    "checkpoint, and the next run resumes it."
)


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("reproduce", help="run the paper's study: 5 networks x 2 strategies + baselines, as FMUs",
                       description=_DESCRIPTION)
    p.add_argument("system", choices=LazyChoices(study_names), metavar="SYSTEM",
                   help="which system: %(choices)s (the studies of the registered physics models)")
    p.add_argument("-o", "--out", required=True, help="study folder (created; re-use it to resume)")
    p.add_argument("--budget", choices=["smoke", "quick", "paper"], default="quick",
                   help="data size, training length and hyperparameters (default quick)")
    p.add_argument("--data", help="dataset folder, or the robot benchmark's .mat file (required for robot)")
    p.add_argument("--tune", action=argparse.BooleanOptionalAction, default=None,
                   help="grid-search the hyperparameters per architecture and strategy on Ray Tune "
                        "(default: on for --budget paper, off otherwise; needs the extra 'tune')")
    p.add_argument("--address", help="a running Ray cluster: the cells run there as Ray tasks, resumable, and the "
                                     "results are written to --out here (default: this machine)")
    p.add_argument("--jobs", type=int, default=1, help="cells run at once in local processes (default 1); with "
                                                       "--address, Ray tasks at once (default: the cluster's CPUs)")
    p.add_argument("--seed", type=int, default=0, help="seeds the data, the validation split and training (default 0)")
    p.add_argument("--quiet", action="store_true", help="no progress bars (one line per cell is still printed)")
    add_resource_options(p)
    p.set_defaults(func=_run)


def _run(args: argparse.Namespace) -> int:
    from nnfmu.cli._outputs import check_writable
    from nnfmu.study import reproduce

    check_writable(Path(args.out) / "results.md")  # before the study's first cell
    if not args.address:  # on a cluster each cell's worker decides (see docs/scaling.md)
        from nnfmu.training.resources import describe_device

        print(f"device: {describe_device(args.device)}", flush=True)
    result = reproduce(args.system, args.out, budget=args.budget, data=args.data, tune=args.tune, seed=args.seed,
                       address=args.address, progress=not args.quiet, jobs=args.jobs, device=args.device,
                       threads=args.threads)
    table = result.results_md.read_text().split("## NRMSE per output")[0]  # title, Table I and its legend
    print(f"\n{table.rstrip()}\n")
    print(f"ran {len(result.log.ran)} cells, skipped {len(result.log.skipped)} done before; results in "
          f"{result.out / 'results.md'} and {result.out / 'results.json'}")
    return 0
