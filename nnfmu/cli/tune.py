"""``nnfmu tune --data DIR --arch A [--strategy S] [--address ADDR] [--search grid|optuna|hyperopt] [--scheduler asha]``.

Search of one architecture's hyperparameters on Ray Tune (the optional
extra ``tune``): the paper's grid search, or Optuna's or HyperOpt's search
algorithm among the grid's values (extra ``search``), with an optional ASHA
scheduler that stops trailing trials early, and CPUs and GPUs per trial. The base configuration and the grid come
from the budget table of the dataset's system (:mod:`nnfmu.study.budgets`);
``--grid`` replaces the grid. Prints the trials, writes the best
hyperparameters as JSON and the ``nnfmu train`` line that uses them.
"""

from __future__ import annotations

import argparse
import contextlib
from pathlib import Path

from nnfmu.cli._arch import LazyChoices
from nnfmu.cli._physics_info import study_names
from nnfmu.cli._resources import add_device_option
from nnfmu.cli._text import description

_TRAIN_FLAGS = {"hidden": "--hidden", "layers": "--layers", "window": "--window", "dropout": "--dropout",
                "lr": "--lr", "weight_decay": "--weight-decay", "clip": "--clip", "batch_size": "--batch-size",
                "truncate": "--truncate"}


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("tune", help="grid-search an architecture's hyperparameters on Ray Tune (extra 'tune')",
                       description=description(__doc__))
    p.add_argument("--data", required=True, help="dataset folder")
    p.add_argument("--arch", required=True, choices=LazyChoices(_tunable_names), metavar="ARCH",
                   help="the architecture whose hyperparameters are searched: %(choices)s (every registered one "
                        "whose config the hyperparameters make alone; plugins: $NNFMU_PLUGINS, entry points)")
    p.add_argument("--strategy", choices=["parallel", "series-parallel"], default="parallel",
                   help="training strategy of every trial (default parallel)")
    p.add_argument("--address", help="address of a running Ray cluster (default: start a local instance)")
    p.add_argument("--cpus", type=int, help="CPUs of the local Ray instance (default: all); one per trial")
    p.add_argument("--samples", type=int, default=1,
                   help="repetitions of every grid point with other seeds (default 1)")
    p.add_argument("--max-minutes", type=float, help="wall-clock cap of each trial in minutes (default: the budget's)")
    p.add_argument("--epochs", type=int, help="maximum epochs of each trial (default: the budget's)")
    p.add_argument("--patience", type=int, help="early-stopping patience of each trial (default: the budget's)")
    p.add_argument("--budget", choices=["smoke", "quick", "paper"], default="quick",
                   help="where the base configuration and the grid come from (default quick)")
    p.add_argument("--system", choices=LazyChoices(study_names), metavar="SYSTEM",
                   help="system of the budget table: %(choices)s (default: read from the dataset's source)")
    p.add_argument("--grid", nargs="+", metavar="FIELD=V1,V2", help="grid to search instead of the budget's, "
                   "e.g. --grid hidden=16,32 lr=0.001,0.003")
    p.add_argument("--seed", type=int, default=0, help="training seed of the first repetition (default 0)")
    p.add_argument("--storage",
                   help="folder for Ray's trial records (default ~/ray_results; on a cluster, a shared one)")
    p.add_argument("-o", "--out", default="best.json",
                   help="where to write the best hyperparameters (default best.json)")
    p.add_argument("--search", choices=["grid", "optuna", "hyperopt"], default="grid",
                   help="every grid point (default), or a search algorithm choosing among the grid's values "
                        "(extra 'search': pip install \"nnfmu[search]\")")
    p.add_argument("--trials", type=int, help="trials of --search optuna|hyperopt (default: the grid's size)")
    p.add_argument("--scheduler", choices=["fifo", "asha"], default="fifo",
                   help="fifo: every trial runs to its end (default); asha: stop trailing trials early")
    p.add_argument("--grace-epochs", type=int, default=1, help="asha: epochs before a trial may be stopped (default 1)")
    p.add_argument("--cpus-per-trial", type=float, default=None,
                   help="CPUs Ray reserves for each trial, used as its torch threads (default 1, or --threads)")
    p.add_argument("--threads", type=int, metavar="N",
                   help="torch threads of each trial; Ray reserves as many CPUs for it (default 1)")
    p.add_argument("--quiet", action="store_true",
                   help="no Ray trial tables or log lines: only the result (Ray's verbose=0, its and Optuna's "
                        "loggers at WARNING)")
    p.add_argument("--gpus-per-trial", type=float, default=None,
                   help="GPUs Ray reserves for each trial, a fraction shares one (default: 1 with --device cuda, "
                        "or auto where Ray has a GPU; 0 with --device cpu, which refuses more)")
    add_device_option(p, what="each trial", extra=" (a trial sees its reserved GPU alone, as cuda:0; cuda:N gives "
                      "the local Ray instance this machine's GPU N alone; with --address, Ray picks each trial's GPU "
                      "and cuda:N is refused)")
    p.set_defaults(func=_run)


def _tunable_names() -> tuple[str, ...]:
    from nnfmu.cli._arch import tunable
    from nnfmu.models import architectures

    return architectures.names(tunable)


def parse_grid(items: list[str]) -> dict[str, tuple]:
    """``["hidden=16,32", "lr=1e-3,3e-3"]`` -> ``{"hidden": (16, 32), "lr": (0.001, 0.003)}``."""
    import dataclasses
    import typing

    from nnfmu.errors import ConfigError, check_options
    from nnfmu.study import Hyper

    from nnfmu.cli._checks import RULES, check_value

    types = typing.get_type_hints(Hyper)
    grid = {}
    for item in items:
        name, sep, values = item.partition("=")
        if not sep or not values:
            raise ConfigError(f"--grid expects FIELD=V1,V2,..., got {item!r}")
        check_options({name: None}, {f.name for f in dataclasses.fields(Hyper)}, "--grid")
        convert = float if types[name] is float else int
        try:
            grid[name] = tuple(None if v == "none" else convert(v) for v in values.split(","))
        except ValueError as exc:
            raise ConfigError(f"--grid {name}: {exc}; give {convert.__name__} values separated by commas") from exc
        rule = RULES.get(("train", name)) or RULES.get(name)  # the same range as the train option of that name
        for value in grid[name]:
            if rule is not None and value is not None:
                check_value(f"--grid {name}", value, rule)
    return grid


def _system(args, ds) -> str:
    from nnfmu.errors import ConfigError

    if args.system:
        return args.system
    from nnfmu.study.data_check import declared_system

    declared = declared_system(ds)
    if declared is not None:
        return declared
    raise ConfigError(f"cannot tell which system {args.data} holds (its source names none); pass --system "
                      f"{'|'.join(study_names())} to choose the base configuration and the grid")


def _cpus_per_trial(args: argparse.Namespace) -> float:
    """``--threads`` and ``--cpus-per-trial`` say the same (a trial's torch threads are its CPUs): one or both."""
    from nnfmu.errors import ConfigError

    if args.threads is not None and args.cpus_per_trial not in (None, args.threads):
        raise ConfigError(f"--threads {args.threads} and --cpus-per-trial {args.cpus_per_trial:g} disagree: a trial's "
                          "torch threads are the CPUs Ray reserves for it; give one of them")
    return float(args.threads or args.cpus_per_trial or 1.0)


def _device(args: argparse.Namespace) -> str:
    """``--device`` checked before any work (a local search: against this machine's GPUs), with its line printed."""
    from nnfmu.errors import ConfigError
    from nnfmu.training.resources import check_ray_device, describe_device, resolve_device

    device = check_ray_device(args.device, args.gpus_per_trial, args.address)
    if args.address:
        print(f"device: {device} (trials on the cluster at {args.address}; Ray reserves their GPUs)", flush=True)
        return device
    if resolve_device(device).type == "cpu" and (args.gpus_per_trial or 0) > 0:
        raise ConfigError(f"--gpus-per-trial {args.gpus_per_trial:g}, but torch sees no CUDA device on this "
                          "machine, so the trials would wait for a GPU forever; drop --gpus-per-trial")
    seen = "; a trial sees its GPU as cuda:0 (Ray sets CUDA_VISIBLE_DEVICES)" if device != "cpu" else ""
    print(f"device: {describe_device(device)}{seen}", flush=True)
    return device


@contextlib.contextmanager
def _quiet_output():
    """--quiet: Ray Tune's reporter that honours verbose=0 (the newer one still prints its experiment box), and
    Ray's and Optuna's loggers at WARNING; errors and warnings still show."""
    import logging
    import os
    from unittest import mock

    with contextlib.suppress(ImportError):  # Optuna sets its logger to INFO when first imported: import it first
        import optuna  # noqa: F401
    loggers = [logging.getLogger(name) for name in ("ray", "ray.tune", "ray.train", "optuna")]
    levels = [log.level for log in loggers]
    for log in loggers:
        log.setLevel(logging.WARNING)
    try:
        with mock.patch.dict(os.environ, {"RAY_AIR_NEW_OUTPUT": "0"}):
            yield
    finally:
        for log, level in zip(loggers, levels):
            log.setLevel(level)


def _run(args: argparse.Namespace) -> int:
    from nnfmu.cli._outputs import check_writable
    from nnfmu.data import load_dataset
    from nnfmu.study import TuneSettings, get_budget, require_ray, tune_architecture
    from nnfmu.study.presets import preset_for

    require_ray()  # before loading data: a missing extra is the first thing to say
    check_writable(args.out, args.storage and Path(args.storage) / "x")  # before any trial runs
    cpus_per_trial = _cpus_per_trial(args)
    device = _device(args)
    ds = load_dataset(args.data)
    budget = get_budget(_system(args, ds), args.budget)
    grid = parse_grid(args.grid) if args.grid else budget.grid(args.arch)
    base = budget.hyper.get(args.arch) or preset_for(args.arch)  # an architecture the budget has no preset for
    settings = TuneSettings(epochs=args.epochs or budget.tune_epochs,
                            patience=budget.tune_patience if args.patience is None else args.patience,
                            max_minutes=args.max_minutes or budget.tune_max_minutes, samples=args.samples,
                            seed=args.seed, search=args.search, trials=args.trials, scheduler=args.scheduler,
                            grace_epochs=args.grace_epochs, cpus_per_trial=cpus_per_trial,
                            gpus_per_trial=args.gpus_per_trial, device=device)
    with _quiet_output() if args.quiet else contextlib.nullcontext():
        result = tune_architecture(ds, args.arch, strategy=args.strategy, base=base, grid=grid,
                                   settings=settings, address=args.address, num_cpus=args.cpus,
                                   storage=args.storage, progress=not args.quiet)
    how = f"{args.search} search, {args.scheduler} scheduler"
    print(f"\n{len(result.trials)} trials of {args.arch} ({args.strategy}; {how}); best validation free-run NRMSE "
          f"{result.best_valid_nrmse:.4f} with {result.best.to_dict()}")
    for row in sorted(result.trials, key=lambda r: (r["best_valid_nrmse"] is None, r["best_valid_nrmse"] or 0)):
        point = ", ".join(f"{k}={row[k]}" for k in sorted(grid))
        score = "diverged" if row["best_valid_nrmse"] is None else f"{row['best_valid_nrmse']:.4f}"
        print(f"  {point or 'base'} (repeat {row['repeat']}): {score} after {row['epochs']} epochs")
    print(f"wrote {result.save(args.out)}")
    flags = " ".join(f"{_TRAIN_FLAGS[k]} {v}" for k, v in result.best.to_dict().items()
                     if k in _TRAIN_FLAGS and v is not None)
    print(f"train with: nnfmu train --data {args.data} --arch {args.arch} --strategy {args.strategy} {flags} "
          "--out model.pt")
    return 0
