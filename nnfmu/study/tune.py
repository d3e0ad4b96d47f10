"""Hyperparameter search on Ray Tune (``nnfmu tune`` and ``nnfmu reproduce --tune``).

Every trial trains one network with :func:`nnfmu.training.train` and reports
the validation free-run NRMSE to Tune after every epoch (the metric early
stopping uses too). The grid spans a few fields of :class:`~nnfmu.study.Hyper`
around an architecture's base configuration. With the ``grid`` search (the
paper's) every grid point is repeated ``samples`` times with different
training seeds; with ``optuna`` or ``hyperopt`` (Ray Tune's integrations, the
optional extra ``search``) that algorithm picks ``trials`` points among the
grid's values, seeded. The ``asha`` scheduler stops trials early whose
validation NRMSE trails the others' at the same epoch (asynchronous successive
halving). Each trial gets ``cpus_per_trial`` CPUs (and as many torch threads)
and trains on ``device`` with ``gpus_per_trial`` GPUs (default: from the device,
:func:`~nnfmu.training.resources.gpus_per_training`; a trial sees its GPU as ``cuda:0``).
The point with the lowest mean best-validation NRMSE wins.

Ray is the optional extra ``tune`` (``pip install "nnfmu[tune]"``, or
``pip install "ray[tune]"``). By default a local Ray instance of its own is started, even beside a cluster running
on this machine (``ray.init(address="local", num_cpus=..., include_dashboard=False)``), and stopped again; with
``address`` the search runs on an existing cluster, whose workers must have
nnfmu installed. The dataset travels to the workers through Ray's object
store, so no shared file system is needed for the data.
"""

from __future__ import annotations

import dataclasses
import itertools
import json
import math
import os
import importlib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Mapping, Sequence

import numpy as np

from nnfmu.data import Dataset
from nnfmu.errors import ConfigError, NnfmuError, TrainingError
from nnfmu.study.budgets import Hyper
from nnfmu.atomic import write_text_atomic
from nnfmu.study.ray_connect import MissingExtraError, ray_session, require_ray
from nnfmu.training import STRATEGIES
from nnfmu.training.resources import check_ray_device, cuda_visible, gpus_per_training

METRIC = "best_valid_nrmse"
SEARCHES = ("grid", "optuna", "hyperopt")
SCHEDULERS = ("fifo", "asha")
# search algorithm -> (module of Ray Tune's integration, class, the package it needs)
_SEARCHERS = {"optuna": ("ray.tune.search.optuna", "OptunaSearch", "optuna"),
              "hyperopt": ("ray.tune.search.hyperopt", "HyperOptSearch", "hyperopt")}


@dataclass(frozen=True, kw_only=True)
class TuneSettings:
    """How long each trial trains and how often each grid point is tried.

    Attributes
    ----------
    epochs, patience : int
        Maximum epochs and early-stopping patience of one trial.
    max_minutes : float or None
        Wall-clock cap of one trial, in minutes.
    samples : int
        Repetitions of every grid point, with training seeds ``seed, seed + 1, ...`` (grid search).
    seed : int
        Training seed (of the first repetition), and the search algorithm's seed.
    search : {'grid', 'optuna', 'hyperopt'}
        Every grid point, or a search algorithm choosing among the grid's values.
    trials : int or None
        Trials of a search algorithm (default: as many as the grid has points).
    scheduler : {'fifo', 'asha'}
        Run every trial to its end, or stop the trailing ones early (ASHA).
    grace_epochs : int
        ASHA: epochs every trial runs before it may be stopped.
    cpus_per_trial : float
        CPUs Ray reserves for one trial (and its torch threads).
    device : {'cpu', 'auto', 'cuda', 'cuda:N'}
        Where the trials train (default cpu); see the module docstring.
    gpus_per_trial : float or None
        GPUs Ray reserves for one trial (a fraction lets trials share one); None: from ``device``.
    """

    epochs: int = 10
    patience: int = 5
    max_minutes: float | None = None
    samples: int = 1
    seed: int = 0
    search: str = "grid"
    trials: int | None = None
    scheduler: str = "fifo"
    grace_epochs: int = 1
    cpus_per_trial: float = 1.0
    gpus_per_trial: float | None = None
    device: str = "cpu"

    def __post_init__(self) -> None:
        for name, low in (("samples", 1), ("grace_epochs", 1)):
            if not isinstance(getattr(self, name), int) or getattr(self, name) < low:
                raise ConfigError(f"{name} must be an integer >= {low}, got {getattr(self, name)!r}")
        if self.trials is not None and (not isinstance(self.trials, int) or self.trials < 1):
            raise ConfigError(f"trials must be None or an integer >= 1, got {self.trials!r}")
        for name, allowed in (("search", SEARCHES), ("scheduler", SCHEDULERS)):
            if getattr(self, name) not in allowed:
                raise ConfigError(f"unknown {name} {getattr(self, name)!r}; choose one of {', '.join(allowed)}")
        if not (isinstance(self.cpus_per_trial, (int, float)) and self.cpus_per_trial >= 1):
            raise ConfigError(f"cpus_per_trial must be >= 1, got {self.cpus_per_trial!r}")
        if self.gpus_per_trial is not None and not (isinstance(self.gpus_per_trial, (int, float))
                                                    and self.gpus_per_trial >= 0):
            raise ConfigError(f"gpus_per_trial must be >= 0 (a fraction shares a GPU), got {self.gpus_per_trial!r}")
        object.__setattr__(self, "device", check_ray_device(self.device, self.gpus_per_trial))

    @property
    def threads(self) -> int:
        """Torch threads of one trial: its whole CPUs."""
        return max(1, int(self.cpus_per_trial))


@dataclass(frozen=True)
class TuneResult:
    """The outcome of one search: the best hyperparameters and every trial's score.

    ``trials`` holds one dict per trial: the grid values, the repeat index, the best validation
    NRMSE and the epochs it ran.
    """

    arch: str
    strategy: str
    best: Hyper
    best_valid_nrmse: float
    trials: list = field(default_factory=list)
    ray_version: str = ""

    def to_json(self) -> dict:
        return {"format": "nnfmu-tune", "arch": self.arch, "strategy": self.strategy, "best": self.best.to_dict(),
                "best_valid_nrmse": _finite_or_none(self.best_valid_nrmse), "ray_version": self.ray_version,
                "trials": self.trials}

    def save(self, path: str | os.PathLike) -> Path:
        return write_text_atomic(Path(path), json.dumps(self.to_json(), indent=2) + "\n")

    @classmethod
    def load(cls, path: str | os.PathLike) -> "TuneResult":
        from nnfmu.errors import DataFileError

        try:
            doc = json.loads(Path(path).read_text())
            score = doc["best_valid_nrmse"]
            return cls(doc["arch"], doc["strategy"], Hyper.from_dict(doc["best"]),
                       math.inf if score is None else float(score), doc.get("trials", []), doc.get("ray_version", ""))
        except (OSError, ValueError, KeyError) as exc:
            raise DataFileError(f"{path} is not a tune result written by nnfmu ({exc}); "
                                "run 'nnfmu tune' again") from exc


def _finite_or_none(x: float):
    return float(x) if math.isfinite(x) else None


def grid_points(grid: Mapping[str, Sequence]) -> list[dict]:
    """Every combination of the grid's values (one dict each); a grid with no fields has one empty point."""
    keys = sorted(grid)
    return [dict(zip(keys, values)) for values in itertools.product(*(tuple(grid[k]) for k in keys))]


def check_grid(arch: str, base: Hyper, grid: Mapping[str, Sequence], n_u: int, n_y: int) -> None:
    """Build every grid point's configs, the network's and the training's, now: a bad value (``lr=nan``) fails
    before Ray starts, not in every trial."""
    for point in grid_points(grid):
        try:
            hyper = base.replace(**point)
            hyper.model_config(arch, n_u, n_y)
            hyper.train_config(strategy=STRATEGIES[0], epochs=1, patience=0, seed=0, max_minutes=None)
        except NnfmuError as exc:
            raise ConfigError(f"tune grid point {point} is invalid for {arch}: {exc}") from exc


def _trial(config: dict, dataset: Dataset | None = None, job: dict | None = None) -> None:
    """One Ray Tune trial: train with the grid point's hyperparameters, report every epoch."""
    from ray import tune

    from nnfmu.training import train

    point = {k: v for k, v in config.items() if k != "repeat"}
    hyper = Hyper.from_dict(job["base"]).replace(**point)
    settings = TuneSettings(**job["settings"])
    train_config = hyper.train_config(strategy=job["strategy"], epochs=settings.epochs, patience=settings.patience,
                                      seed=settings.seed + int(config.get("repeat", 0)),
                                      max_minutes=settings.max_minutes)

    def report(epoch: int, metrics: dict) -> None:
        tune.report({"epoch": epoch, "valid_nrmse": _finite(metrics["valid_nrmse"]),
                     METRIC: _finite(metrics["best_valid_nrmse"])})

    try:
        train(dataset, hyper.model_config(job["arch"], dataset.n_u, dataset.n_y), train_config, callback=report,
              device=job["device"], threads=settings.threads)
    except TrainingError:  # a diverging configuration is a bad score, not a failed search
        tune.report({"epoch": 0, "valid_nrmse": math.inf, METRIC: math.inf})


def _finite(x: float) -> float:
    return float(x) if math.isfinite(x) else math.inf


def tune_architecture(dataset: Dataset, arch: str, *, strategy: str = "parallel", base: Hyper | None = None,
                      grid: Mapping[str, Sequence] | None = None, settings: TuneSettings | None = None,
                      address: str | None = None, num_cpus: int | None = None,
                      storage: str | os.PathLike | None = None, progress: bool = False) -> TuneResult:
    """Search the hyperparameters of ``arch`` trained with ``strategy`` on Ray Tune (see the module docstring).

    Parameters
    ----------
    dataset : Dataset
        Needs a 'valid' split, or one is carved out of train by the trainer (the same in every trial).
    base : Hyper
        The base configuration; grid values replace its fields. Default ``Hyper()``.
    grid : mapping field -> values
        E.g. ``{"hidden": (16, 32), "lr": (1e-3, 3e-3)}``; empty: only the base configuration.
    settings : TuneSettings
        Trial length, repetitions, seed, search algorithm, scheduler and resources per trial.
    address : str, optional
        Address of a running Ray cluster (``ray start --head`` prints it); default: a local instance.
    num_cpus : int, optional
        CPUs of the local instance (default: all); each trial takes ``settings.cpus_per_trial``.
    storage : path, optional
        Folder for Ray's trial records (default ``~/ray_results``); on a cluster, a shared one.
    """
    ray, tune = require_ray()
    if strategy not in STRATEGIES:
        raise ConfigError(f"unknown strategy {strategy!r}; choose one of {', '.join(STRATEGIES)}")
    base, grid, settings = base or Hyper(), dict(grid or {}), settings or TuneSettings()
    check_grid(arch, base, grid, dataset.n_u, dataset.n_y)
    check_ray_device(settings.device, settings.gpus_per_trial, address)
    run_config = tune.RunConfig(name=f"nnfmu-{arch}-{strategy}", verbose=1 if progress else 0,
                                storage_path=None if storage is None else str(Path(storage).resolve()))
    space, tune_config = _search(tune, grid, settings)
    with ray_session(address, num_cpus, num_gpus=None if address else _local_gpus(settings), quiet=not progress,
                     cuda_visible=cuda_visible(settings.device)) as session:
        gpus = gpus_per_training(settings.device, session.cluster_resources().get("GPU", 0), settings.gpus_per_trial)
        # a trial that reserved a GPU sees it alone, renumbered cuda:0 (Ray sets CUDA_VISIBLE_DEVICES)
        job = {"arch": arch, "strategy": strategy, "base": base.to_dict(), "settings": dataclasses.asdict(settings),
               "device": "cuda" if gpus > 0 else "cpu"}
        resources = {"cpu": settings.cpus_per_trial, "gpu": gpus}
        trainable = tune.with_resources(tune.with_parameters(_trial, dataset=dataset, job=job), resources)
        results = tune.Tuner(trainable, param_space=space, run_config=run_config, tune_config=tune_config).fit()
        trials = [_trial_row(r, grid) for r in results]
    return _best(arch, strategy, base, grid, trials, ray.__version__)


def _search(tune, grid: Mapping[str, Sequence], settings: TuneSettings) -> tuple[dict, object]:
    """The parameter space and the TuneConfig (search algorithm, scheduler, number of trials)."""
    scheduler = None
    if settings.scheduler == "asha":
        from ray.tune.schedulers import ASHAScheduler

        scheduler = ASHAScheduler(time_attr="epoch", max_t=settings.epochs,
                                  grace_period=min(settings.grace_epochs, settings.epochs), reduction_factor=2)
    if settings.search == "grid":
        space = {k: tune.grid_search(list(v)) for k, v in grid.items()}
        space["repeat"] = tune.grid_search(list(range(settings.samples)))
        return space, tune.TuneConfig(metric=METRIC, mode="min", reuse_actors=True, scheduler=scheduler)
    if not grid:
        raise ConfigError(f"the {settings.search} search needs a grid of at least one field to choose from, "
                          "e.g. --grid hidden=16,32 lr=0.001,0.003")
    module, name, package = _SEARCHERS[settings.search]
    try:
        searcher_class = getattr(importlib.import_module(module), name)
        seeded = ({"sampler": importlib.import_module("optuna").samplers.TPESampler(seed=settings.seed)}
                  if settings.search == "optuna" else {"random_state_seed": settings.seed})
        from nnfmu.study.no_repeat import NoRepeat

        searcher = NoRepeat(searcher_class(**seeded))  # a grid point is trained once, however often proposed
    except (ImportError, AssertionError) as exc:  # Ray's integrations assert that their package is there
        raise MissingExtraError(f"the {settings.search} search needs {package}, which is not installed ({exc}); "
                                f"install the optional extra with: pip install \"nnfmu[search]\" "
                                f"(or pip install {package})") from exc
    space = {k: tune.choice(list(v)) for k, v in grid.items()}
    trials = settings.trials or len(grid_points(grid))
    return space, tune.TuneConfig(metric=METRIC, mode="min", reuse_actors=True, scheduler=scheduler,
                                  search_alg=searcher, num_samples=trials)


def _local_gpus(settings: TuneSettings) -> float | None:
    """GPUs of a local Ray instance: none for CPU trials; otherwise Ray detects them (those of CUDA_VISIBLE_DEVICES)."""
    return 0 if gpus_per_training(settings.device, 1, settings.gpus_per_trial) == 0 else None


def _trial_row(result, grid: Mapping) -> dict:
    metrics = result.metrics or {}
    score = metrics.get(METRIC, math.inf)
    row = {k: result.config[k] for k in sorted(grid)}
    row.update(repeat=int(result.config.get("repeat", 0)), best_valid_nrmse=_finite_or_none(_finite(score)),
               epochs=int(metrics.get("epoch", 0)), error=None if result.error is None else str(result.error))
    return row


def _best(arch: str, strategy: str, base: Hyper, grid: Mapping, trials: list[dict], version: str) -> TuneResult:
    scores: dict[tuple, list[float]] = {}
    for row in trials:
        key = tuple(row[k] for k in sorted(grid))
        score = row["best_valid_nrmse"]
        scores.setdefault(key, []).append(math.inf if score is None else score)
    if not scores:
        raise TrainingError(f"the search for {arch} {strategy} produced no trial results; see Ray's log above")
    key, values = min(scores.items(), key=lambda kv: float(np.mean(kv[1])))  # ties: first grid point
    best = base.replace(**dict(zip(sorted(grid), key)))
    return TuneResult(arch, strategy, best, float(np.mean(values)), trials, version)
