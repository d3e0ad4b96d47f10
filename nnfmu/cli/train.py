"""``nnfmu train --data DIR --arch ARCH --strategy STRATEGY --out model.pt [options]``.

Trains one network with the one trainer, shows a progress bar with the loss
and the validation free-run NRMSE, writes the checkpoint after every epoch,
and prints the free-run test NRMSE of the best weights. Ctrl-C (or SIGTERM)
stops and keeps the best checkpoint (exit status 130, or 143 for SIGTERM);
``--resume`` continues it. A run that fails or stops before its first epoch
finishes leaves nothing at ``--out``; sizes are checked against
:mod:`nnfmu.limits` before anything is allocated.

``--arch`` offers every registered architecture (:mod:`nnfmu.models.architectures`, :mod:`nnfmu.cli._arch`):
the five networks, the hybrid (``--arch hybrid --physics NAME [--physics-params FILE.json]``: a physics
model plus a neural correction, :mod:`nnfmu.hybrid`) and those of plugins (an installed package's
``nnfmu.architectures`` entry point, or a module named in ``NNFMU_PLUGINS``). An architecture's own options
come from its record, and so do its strategies and training dtype.

The command reads top to bottom: parse (:func:`register`, :func:`request`: the command line as a
:class:`~nnfmu.cli._train_plan.TrainRequest`) -> plan (:func:`nnfmu.cli._train_plan.make_plan`: checks, data,
configs and the choices left to the data, as a :class:`~nnfmu.cli._train_plan.TrainPlan`) -> run (:func:`run`:
a search, both output modes, seeds, or one training) -> report (:mod:`nnfmu.cli._train_variants`). Every stage
after the parse gets the plan.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from nnfmu.cli import _arch
from nnfmu.cli._resources import add_resource_options
from nnfmu.cli._train_plan import REFIT, TrainPlan, TrainRequest, make_plan
from nnfmu.cli._train_search import run_search
from nnfmu.cli._train_variants import print_test, report_end, run_both_modes, run_seeds
from nnfmu.training.config import LR_SCHEDULES

_DESCRIPTION = (
    "Train a network on a dataset folder, parallel (free-run loss) or series-parallel (one-step-ahead "
    "loss). A progress bar shows the loss and the validation free-run NRMSE; the checkpoint is written "
    "after every epoch and the free-run test NRMSE of the best weights is printed at the end. Ctrl-C "
    "stops and keeps the best checkpoint; --resume continues it."
)

# (option, ModelConfig/TrainConfig field, type, help). The defaults live in the config classes; the
# "(default ...)" texts are checked against them by tests/test_train_cli.py.
_MODEL_OPTIONS = (
    ("--hidden", "hidden", int, "width of the hidden layers / recurrent state (default 32)"),
    ("--layers", "layers", int, "hidden layers (MLP), stacked recurrent layers, or TCN layers (default per arch)"),
    ("--window", "window", int, "past samples seen by the MLP (default 4); the TCN's must equal its receptive field"),
    ("--dropout", "dropout", float, "dropout probability on hidden activations (default 0)"),
    ("--init-window", "init_window", int,
     "N: the initial state is estimated from the N measured samples up to t0 (RNN/LSTM/GRU: a learned encoder; "
     "MLP/TCN: their own window; hybrid: its FMU's least-squares estimator, in training too); 1 = from y0 and u0 "
     "alone (default 1)"),
)
_TRAIN_OPTIONS = (
    ("--lr", "lr", float, "AdamW learning rate (default 3e-3)"),
    ("--weight-decay", "weight_decay", float, "AdamW weight decay (default 1e-4)"),
    ("--clip", "clip", float, "gradient-norm clipping, 0 = off (default 1)"),
    ("--epochs", "epochs", int, "maximum epochs (default 100)"),
    ("--patience", "patience", int, "early-stopping patience in epochs, 0 = off (default 15)"),
    ("--batch-size", "batch_size", int, "trajectories or windows per step (default 64)"),
    ("--truncate", "truncate", int, "train on windows of N samples (default: whole trajectories): each epoch "
     "cuts every trajectory into consecutive, non-overlapping windows (stride N) from a random offset below N, "
     "drops the shorter tail, starts each window from its measured first output and shuffles all windows "
     "into batches"),
    ("--seed", "seed", int, "random seed (default 0)"),
    ("--max-minutes", "max_minutes", float, "wall-clock budget in minutes (default: 10, with the step budget the "
     "data give). Alone (without --epochs and --patience) it means: spend the budget on a small search (one worker "
     "a core, successive halving; architecture when --arch is left out, width, learning rate, feedback noise, "
     "window; trial 0 is the plain training), keep the best on validation and print the search as a table. With "
     "--epochs the bar counts epochs"),
    ("--feedback-noise", "feedback_noise", float,
     "std of noise added to the fed-back output in training, in output standard deviations (default 0)"),
    ("--average", "average", str, "weight averaging: none, ema or swa (default: none)"),
    ("--lr-schedule", "lr_schedule", str, "learning-rate schedule: constant; cosine over --epochs; plateau (x0.3 "
     "after a quarter of the patience without a better validation score, from the best weights); anneal (constant "
     "until the patience runs out, then x0.1 from the best weights with a quarter of the patience, twice) "
     "(default: constant)"),
    ("--valid-fraction", "valid_fraction", float, "one training record without a valid split: the share held out "
     "for validation (default: min(test length, 25 %%) of the record, at least 10 %%, chosen from the data; 0.1 for "
     "several trajectories: that share of them, at random)"),
    ("--valid-blocks", "valid_blocks", int, "one training record: hold out --valid-fraction as K blocks spread over "
     "the record instead of its tail (default 1: the tail)"),
    ("--physics-schedule", "physics_schedule", str, "a hybrid's trained physical parameters (--train-physics): "
     "joint (with the network from the start) or staged (frozen first, then joint at a tenth of the learning "
     "rate) (default: joint)"),
    ("--valid-horizon", "valid_horizon", str,
     "validation free runs: split (each trajectory), joined (end to end), auto (joined for contiguous pieces "
     "when the test is longer; default: auto)"),
)
# Switches (--X, and --no-X to override a planned default), model or training fields.
_FLAG_OPTIONS = (
    ("--join", "join", "join the training trajectories end to end before cutting --truncate windows (data cut "
                       "from one continuous recording; default: joined when the dataset says its records are "
                       "consecutive pieces, as the robot benchmark's)"),
)
_CHOICES = {"average": ("none", "ema", "swa"), "lr_schedule": LR_SCHEDULES,
            "valid_horizon": ("auto", "split", "joined"), "physics_schedule": ("joint", "staged")}



def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("train", help="train a network (parallel or series-parallel) on a dataset folder",
                       description=_DESCRIPTION)
    p.add_argument("--data", required=True, help="dataset folder (meta.json, train.npz, test.npz[, valid.npz])")
    p.add_argument("--arch", choices=_arch.LazyChoices(_architecture_names), metavar="ARCH",
                   help="the architecture: %(choices)s (an architecture's own options are listed under its name "
                        "below; plugins: the modules named in $NNFMU_PLUGINS, and installed packages' entry points "
                        "'nnfmu.architectures')")
    p.add_argument("--strategy", choices=["parallel", "series-parallel"],
                   help="parallel (free-run loss, default) or series-parallel (one-step-ahead loss)")
    p.add_argument("-o", "--out", required=True, help="checkpoint file to write (.pt)")
    for flag, dest, typ, text in _MODEL_OPTIONS + _TRAIN_OPTIONS:
        p.add_argument(flag, dest=dest, type=typ, default=None, choices=_CHOICES.get(dest), help=text)
    for flag, dest, text in _FLAG_OPTIONS:
        p.add_argument(flag, dest=dest, action=argparse.BooleanOptionalAction, default=None, help=text)
    p.add_argument("--increment", nargs="?", const="on", choices=["on", "auto"], default=None,
                   help="increment mode for integrating plants: predict y[k+1]-y[k] scaled by the data's "
                        "increments, inputs relative to the newest output. 'auto' trains the network both ways "
                        "(into <out stem>.residual.pt and .increment.pt) and keeps the one with the lower "
                        "validation NRMSE")
    p.add_argument("--linear-path", default="auto", metavar="auto|off|FILE.json",
                   help="auto (default): identify the linear baseline first and train the network as a correction "
                        "to it, starting at zero, so training starts at the linear model's error and the kept "
                        "weights are never worse on validation; FILE.json: start from a linear model saved by "
                        "'nnfmu linear --save'; off: the network alone. Windows, batch, budget and validation tail "
                        "left out are chosen from the data and printed")
    seeds = p.add_argument_group("seeds (several trainings of the same network)")
    seeds.add_argument("--seeds", type=int, metavar="K",
                       help="train K seeds (--seed, +1, ...) into <out stem>.seeds/ and write the kept model to --out "
                            "(default: one per usable core, at least 2 and at most 8, side by side, then further "
                            "waves while the plan's minutes leave room for one more, up to 8 in all, when the plan "
                            "chooses the budget, no --epochs or --max-minutes, and a core is idle beside the "
                            "training, else 1; --seeds 1: one network)")
    seeds.add_argument("--keep", choices=["select", "best", "ensemble"],
                       help="select (default): the seed best on validation, joined by others only where their "
                            "ensemble lowers the validation NRMSE by 1 %%; best: the best on validation alone; "
                            "ensemble: all K (their mean output fed back; one FMU)")
    seeds.add_argument("--jobs", type=int, help="with --seeds: seeds trained at once (default: the usable cores)")
    seeds.add_argument("--refit", action=argparse.BooleanOptionalAction, default=None,
                       help="after choosing on validation, train each kept seed once more from its seed on the "
                            "training and validation data together, for the epochs it kept, into <out stem>.seeds/"
                            "refit-<s>.pt, and keep those weights (about as long again; the validation score printed "
                            "is then the one the model was chosen by; default: %s)" % ("on" if REFIT else "off"))
    _arch.add_architecture_options(p)
    p.add_argument("--resume", action="store_true", help="continue the training stored in --out")
    p.add_argument("--force", action="store_true",
                   help="overwrite an existing --out file, and the seeds in <out stem>.seeds/ trained with other "
                        "settings")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    add_resource_options(p)
    p.set_defaults(func=_run)


def _architecture_names() -> tuple[str, ...]:
    from nnfmu.models import architectures

    return architectures.names()


def _given(args: argparse.Namespace, options) -> dict:
    return {dest: getattr(args, dest) for _, dest, _, _ in options if getattr(args, dest) is not None}


def request(args: argparse.Namespace) -> TrainRequest:
    """The parse stage's result: what the command line asked, options left out omitted."""
    train_options = _given(args, _TRAIN_OPTIONS)
    if args.join is not None:
        train_options["join"] = args.join
    return TrainRequest(data=args.data, out=Path(args.out), arch=args.arch, strategy=args.strategy,
                        model_options=_given(args, _MODEL_OPTIONS), train_options=train_options,
                        arch_options=_arch.given_values(args), increment=args.increment, linear_path=args.linear_path,
                        seeds=args.seeds, keep=args.keep, jobs=args.jobs, refit=args.refit, resume=args.resume,
                        force=args.force, quiet=args.quiet, device=args.device, threads=args.threads)


def _run(args: argparse.Namespace) -> int:
    return run(make_plan(request(args)))


def run(plan: TrainPlan) -> int:
    """The run stage: a search (``--max-minutes`` alone), both output modes (``--increment auto``), seeds, or one
    training; returns the exit status."""
    if plan.search:
        return run_search(plan)
    if plan.request.increment == "auto":
        return run_both_modes(plan, run_one)
    if plan.seeds is not None and plan.seeds > 1:  # --seeds 1 is one plain training
        return run_seeds(plan)
    return run_one(plan)


def run_one(plan: TrainPlan) -> int:
    """One training into ``plan.out`` (or its resumption), with the summary printed."""
    import signal

    from nnfmu.cli._outputs import remove_if_untrained
    from nnfmu.training import train

    request, out = plan.request, plan.out
    try:
        result = train(plan.data, plan.model_config, plan.train_config, out=out, resume=request.resume,
                       progress=plan.progress, device=plan.device, threads=request.threads, linear=plan.linear,
                       say=lambda line: print(line, flush=True))
    except BaseException:
        if not request.resume:  # a failed command leaves nothing at --out unless an epoch finished
            remove_if_untrained(out)
        raise
    for note in result.notes:
        print(f"note: {note}")
    if result.stop_reason in ("SIGINT", "SIGTERM"):
        status = 128 + getattr(signal, result.stop_reason)
        if not request.resume and remove_if_untrained(out):
            print(f"interrupted before the first epoch finished: nothing was kept at {out}")
            return status
        print(f"stopped: {result.stop_reason}; best epoch {result.best_epoch}, validation free-run NRMSE "
              f"{result.best_valid_nrmse:.4f}; checkpoint {out}")
        print(f"interrupted: the best checkpoint so far is kept; continue with --resume --out {out}")
        return status
    print(f"stopped: {result.stop_reason}; best epoch {result.best_epoch}, "
          f"validation free-run NRMSE {result.best_valid_nrmse:.4f}; checkpoint {out}")
    report_end(result, plan.linear)
    if result.test is None:
        print("test free-run NRMSE: n/a (no test split, or the free run diverged)")
        return 0
    print_test(plan.data, result.test, result.test_window, plan.model_config.init_window)
    return 0
