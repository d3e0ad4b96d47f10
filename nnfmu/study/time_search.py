"""``nnfmu train --max-minutes N`` without ``--epochs``: the budget spent on a small early-stopping search.

:func:`search_for` trains the points of :mod:`nnfmu.study.time_space` (trial 0 the plain defaults) in one persistent
worker process a core (:mod:`nnfmu.study.trial_pool`), one torch thread each: a core whose trial ended starts the
next at once. Every trial is :func:`nnfmu.training.train` with the plain training's budget per seed (where the time
alone was given: :data:`~nnfmu.training.plan.BUDGET_STEPS` optimiser steps, patience
:data:`~nnfmu.training.plan.PATIENCE_STEPS` steps, at most :data:`~nnfmu.training.plan.DEFAULT_MINUTES`) and
reports its validation free-run NRMSE after every epoch; asynchronous successive halving
(:class:`~nnfmu.study.trial_pool.Halving`) stops the trials that trail the others at the same epoch (grace period:
:data:`GRACE_STEPS` optimiser steps, at least 3 epochs). Trial 0, the defaults, is never stopped by it: it trains to
its own stop as the plain training would, or to the search's end, so the search is never worse on validation than
the defaults it starts from. The whole search ends within the budget:

- the budget counts from the call, or from ``since`` (``nnfmu train``: from the command's start).
  :data:`END_RESERVE` of it (at least :data:`MIN_RESERVE_S`) is kept for the workers' last epochs and the copy
  of the kept model; before it, the time the ensemble selection and the test scores need (measured: the trials'
  validation free runs times the runs the selection makes, at most :data:`SELECT_SHARE` of the budget);
- a core whose trial ended takes the next point while at least :data:`MIN_TRIAL_S` is left; once every point has
  started (or from :data:`RESEED_AFTER` of the budget on, which is off: 1), one of the best points that trained to
  their own stop again, with the next seed (:func:`~nnfmu.study.time_space.again`), trained to its own stop too; a
  trial stops after an epoch when the next would end past the trials' end.

The trials validate on the validation split only (the test split stays in the driver). At the end a greedy
ensemble selection on validation (:func:`nnfmu.training.ensemble_select.select_ensemble`) keeps one model: another
trial joins as a member (the mean output fed back) only if it lowers the validation free-run NRMSE by 1 % or more,
up to 4 members. Its candidates are the seeds of the point best on the mean of its seeds (:func:`_best_point`),
where a point has :data:`MIN_SEEDS` or more and their ensemble is at or below trial 0 on validation; otherwise the
:data:`MAX_CANDIDATES` best trials that improved on their start, from the best. The mean, not the best draw, ranks
a point: ``benchmarks/search_selection.py`` chose it one level down, without the test split (docs/accuracy.md,
"Which trials a search keeps"). The kept model (one trial's network, or the ensemble of several), with its test
scores added, is written atomically to ``out``. Nothing is written to
``out`` unless a trial finished an epoch. The result says how much of the CPU the trials used (their CPU seconds
over cores x the search's wall time) and when its best validation score last fell.
"""

from __future__ import annotations

import dataclasses
import math
import os
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path

from nnfmu.data import Dataset, save_dataset
from nnfmu.errors import ConfigError
from nnfmu.limits import UNBOUNDED_EPOCHS
from nnfmu.study.time_space import KNOBS, again, label, point_key, trial_configs, trial_points
from nnfmu.study.trial_pool import Halving, Trials, run_trials
from nnfmu.training import TrainConfig
from nnfmu.training.ensemble_select import MAX_MEMBERS
from nnfmu.training.plan import BUDGET_STEPS, DEFAULT_MINUTES, PATIENCE_STEPS
from nnfmu.training.resources import usable_cores

END_RESERVE = 0.02  # of the budget, at least MIN_RESERVE_S
MIN_RESERVE_S = 3.0
MAX_POINTS = 1000  # the whole space, in practice (270 points at most)
MIN_TRIAL_S = 5.0
GRACE_STEPS = 20
SELECT_SHARE = 0.1  # of the budget, at most, kept for the ensemble selection after the trials
MIN_SELECT_S = 2.0
SELECT_SAFETY = 3.0  # an ensemble's free run is in torch, a trial's validation often compiled
MAX_CANDIDATES = 6  # the best trials on validation that the selection tries
MIN_SEEDS = 2  # seeds of one point before the mean of their validation scores ranks it
#: the share of the budget after which a core whose trial ended trains a further seed of one of the best points
#: (:func:`~nnfmu.study.time_space.again`) rather than a new point, where one qualifies; 1: only once every point has
#: started. Measured one level down (``benchmarks/search_selection.py --reseed-after``, docs/accuracy.md): 2/3 kept a
#: worse model on the robot's 10 minutes (outer validation 0.7027 against 0.6844) and the same on the slider's.
RESEED_AFTER = 1.0
#: what successive halving compares a trial with at a rung: "all", every trial, or "arch", the trials of its own
#: architecture (each learns at its own pace per epoch: the ss network leaves its linear start later than the
#: recurrent ones). Measured one level down (``benchmarks/search_selection.py --halving``, docs/accuracy.md):
#: "arch" kept a better model on the robot and the F-16 and a worse one on the slider and the valve, 6.5 % worse
#: on the geometric mean of the outer validation NRMSE.
HALVING_BY = "all"
#: validation free runs of one member the selection makes at most: the best alone, then each round tries every
#: candidate left as one more member of the ensemble so far
SELECT_RUNS = 1 + sum((MAX_CANDIDATES - r) * (r + 1) for r in range(1, MAX_MEMBERS))


@dataclass(frozen=True)
class TimeSearchResult:
    """The search: one row per trial (``rows``), the kept trial's index and checkpoint, the time spent.

    A row: ``trial``, the knobs (``arch``, ``hidden``, ``lr``, ``feedback_noise``, ``truncate``), ``epochs``
    (run), ``best_valid_nrmse`` (kept in its checkpoint; None if it never finished an epoch), ``stopped``
    (by successive halving), ``cpu_s`` (CPU seconds of its training), ``status`` (how it ended) and ``error``.
    ``best``: the trial best on validation; ``members``: the trials of the kept model (one, or the ensemble's, in
    the order the selection added them; the seeds of the best point need not include ``best``) and
    ``member_scores`` the validation NRMSE after each addition; ``best_valid_nrmse``: the kept model's. ``test``
    and ``test_window``: the kept model's free-run test scores (:class:`~nnfmu.metrics.NrmseResult` or None), as
    :class:`~nnfmu.training.TrainResult` has them;
    ``model_config`` and ``train_config``: the kept model's, as its checkpoint holds them (dicts).
    ``usage``: ``cpu_s`` (the trials' CPU seconds), ``cores``, ``wall_s`` (from the call to the end),
    ``cpu_share`` (``cpu_s / (cores * wall_s)``) and ``load`` (the machine's 5-minute load average at the end:
    other work on the cores lowers the share); ``progress``: ``(minutes, trial, validation NRMSE)`` each time the
    best trial so far improved, and ``stalled``: why it stopped improving early, or "".
    """

    rows: list = field(default_factory=list)
    best: int | None = None
    best_valid_nrmse: float = math.inf
    out: Path | None = None
    seconds: float = 0.0
    model_config: dict | None = None
    train_config: dict | None = None
    test: object = None
    test_window: object = None
    members: tuple = ()
    member_scores: tuple = ()
    selection: str = ""
    usage: dict = field(default_factory=dict)
    progress: tuple = ()
    stalled: str = ""


def search_for(dataset: Dataset, minutes: float, *, model_config, train_config: TrainConfig, linear=None,
               out, given=(), seed: int = 0, progress: bool = True, cpus: int | None = None,
               since: float | None = None, keep_trials: Path | None = None) -> TimeSearchResult:
    """Spend ``minutes`` on the search (module docstring); the kept model's checkpoint is written to ``out``.

    ``dataset`` has its validation split; ``model_config`` is the base network (its ``arch`` is trial 0's and is
    searched unless ``"arch"`` is in ``given``; None: the first architecture of the search order,
:func:`~nnfmu.models.architectures.search_order`, on the linear path of ``linear``), ``train_config``
    the planned training (``max_minutes`` is not used: ``minutes`` is the budget; ``epochs`` at
    :data:`~nnfmu.limits.UNBOUNDED_EPOCHS` and ``patience`` 0 mean the plain training's budget per seed), ``linear``
    the linear model of the linear path (or None), ``given`` the names of the options the user gave (kept as given).
    Ctrl-C, SIGTERM or an error during the search still writes the best finished trial to ``out``, then goes on.
    ``since``: the :func:`time.monotonic` time the budget counts from (default: now; the CLI passes its start).
    ``cpus``: worker processes (default: the cores this process may use). ``keep_trials``: a folder to copy every
    trial's checkpoint into (``trial-<i>.pt``), for comparing selection rules offline
    (``benchmarks/search_selection.py``); by default they go with the search's temporary folder.
    """
    called = time.monotonic()
    started = called if since is None else since
    if dataset.valid is None:
        raise ConfigError("the time search needs a dataset with its validation split (carve it first)")
    if model_config is None:
        from nnfmu.models import ModelConfig, architectures

        model_config = ModelConfig(arch=architectures.search_order()[0], n_u=dataset.n_u, n_y=dataset.n_y,
                                   linear_order=0 if linear is None else linear.n_x)
    if not (isinstance(minutes, (int, float)) and minutes > 0):
        raise ConfigError(f"the search budget must be > 0 minutes, got {minutes!r}")
    cpus = max(1, int(cpus or usable_cores()))
    out, given, budget = Path(out), set(given), 60.0 * minutes
    reserve = max(MIN_RESERVE_S, END_RESERVE * budget)
    final = started + budget
    train_config = _resolved(dataset, train_config)
    trials_ds = dataset.replace(splits={k: v for k, v in dataset.splits.items() if k != "test"})
    grace = max(3, math.ceil(GRACE_STEPS / _steps_per_epoch(trials_ds, train_config)))
    points = trial_points(model_config, train_config, given, MAX_POINTS, seed, int(trials_ds.train.lengths.max()))
    test_runs = _test_runs(dataset, train_config, model_config.init_window)
    jobs = _Jobs(points, model_config, train_config, given, trials_ds, grace, reseed_at=started + RESEED_AFTER * budget)
    trials, halving, run = jobs.trials, jobs.halving, jobs.run

    def end() -> float:  # the trials' end: the selection's time measured on the trials' validation runs
        return final - reserve - _select_seconds(trials, test_runs, budget)

    with tempfile.TemporaryDirectory(prefix="nnfmu-search-") as tmp:
        folder = Path(tmp)
        data = save_dataset(dataset, folder / "dataset")  # a dataset folder holds a test split: the workers drop it
        linear_file = None if linear is None else linear.save(folder / "linear.json")
        stopped_by = None
        try:
            run_trials(jobs.job, data=data, folder=folder, linear=linear_file, cpus=cpus, end=end,
                       min_left_s=MIN_TRIAL_S, halving=halving, trials=trials, on_done=jobs.echo if progress else None)
        except BaseException as exc:  # Ctrl-C, SIGTERM or a failure: the best finished trial is still kept
            stopped_by = exc
        rows = [_row(i, run[i], folder, trials.records.get(i, {}), i in halving.stopped)
                for i in range(trials.started)]
        if keep_trials is not None:
            _copy_trials(folder, Path(keep_trials))
        kept = _keep(rows, folder, dataset, out, None if stopped_by is not None else final - reserve / 2)
        if stopped_by is not None:
            if kept is not None:
                print(f"search stopped ({type(stopped_by).__name__}): the best trial so far, {kept.best}, "
                      f"validation free-run NRMSE {kept.best_valid_nrmse:.4f}, is kept in {out}", flush=True)
            raise stopped_by
    seconds = time.monotonic() - started
    usage = _usage(rows, cpus, time.monotonic() - called, trials)
    found = tuple((t / 60.0, i, v) for t, i, v in trials.best)
    extra = dict(rows=rows, seconds=seconds, usage=usage, progress=found,
                 stalled=_stalled(found, rows, (jobs.started_points, len(points)), len(jobs.reseeds),
                                  (end() - called) / 60.0))
    if kept is None:
        return TimeSearchResult(**extra)
    return dataclasses.replace(kept, **extra)


class _Jobs:
    """The trials' jobs: the space's points in order (the training's seed), and :func:`again`'s further seeds once
    every point has started or from ``reseed_at`` (a :func:`time.monotonic` time) on, whichever comes first.

    ``run``: the point of every trial handed out so far, with its ``seed``; ``trials`` and ``halving``: what the
    workers reported and what successive halving stopped; ``reseeds``: the trials that are further seeds."""

    def __init__(self, points: list, model_config, train_config: TrainConfig, given: set, dataset: Dataset,
                 grace: int, reseed_at: float = math.inf):
        self.points, self.model_config, self.train_config, self.given = points, model_config, train_config, given
        self.dataset, self.grace, self.reseed_at = dataset, grace, reseed_at
        self.run, self.trials = [], Trials()
        self.halving = Halving(grace, group=(lambda i: self.run[i]["arch"]) if HALVING_BY == "arch" else None)
        self.started_points, self.reseeds = 0, set()

    def job(self, i: int) -> dict | None:
        """Trial ``i``'s job for a worker; None while every point has started and none trained to its own stop."""
        point = None
        if self.started_points == len(self.points) or time.monotonic() >= self.reseed_at:
            point = again(self.run, self.trials.scores, self.halving.stopped, MAX_CANDIDATES)
        if point is not None:  # a point that trained to its own stop, with another seed: it does so too
            self.halving.exempt.add(i)
            self.reseeds.add(i)
        elif self.started_points < len(self.points):
            point = {**self.points[self.started_points], "seed": self.train_config.seed}
            self.started_points += 1
        else:
            return None
        self.run.append(point)
        mc, tc = trial_configs(point, self.model_config, self.train_config, self.given)
        tc = _budgeted(tc.replace(seed=point["seed"]), _steps_per_epoch(self.dataset, tc), self.grace)
        return {"trial": i, "model_config": mc.to_dict(), "train_config": tc.to_dict()}

    def echo(self, i: int, record: dict) -> None:
        """One printed line as trial ``i`` ends."""
        score = record.get("last", {}).get("best_valid_nrmse")
        text = "no epoch finished" if score is None else (f"best validation NRMSE {score:.4f} after "
                                                          f"{record['last']['epoch']} epochs")
        stopped = ", stopped by successive halving" if i in self.halving.stopped else ""
        print(f"search: trial {i} {label(self.run[i])}: {text}{stopped}", flush=True)


def _copy_trials(folder: Path, to: Path) -> None:
    """Copy the trials' checkpoints from the search's folder into ``to`` (made if missing)."""
    import shutil

    to.mkdir(parents=True, exist_ok=True)
    for ckpt in folder.glob("trial-*.pt"):
        shutil.copy2(ckpt, to / ckpt.name)


def _budgeted(cfg: TrainConfig, steps: int, grace: int) -> TrainConfig:
    """``cfg`` with the plain training's budget per seed where the time alone was the budget (module docstring).

    ``steps``: optimiser steps an epoch of this trial; the patience is at least two grace periods, so that a trial
    that successive halving keeps is not ended by its patience first."""
    changes = {"max_minutes": DEFAULT_MINUTES if cfg.max_minutes is None else min(cfg.max_minutes, DEFAULT_MINUTES)}
    if cfg.epochs >= UNBOUNDED_EPOCHS:
        changes["epochs"] = max(1, math.ceil(BUDGET_STEPS / steps))
    if cfg.patience == 0:
        changes["patience"] = max(2 * grace, math.ceil(PATIENCE_STEPS / steps))
    return cfg.replace(**changes)


def _test_runs(dataset: Dataset, cfg: TrainConfig, init_window: int) -> float:
    """The kept model's test scores in validation free runs of one member: float64 (about twice the cost), a second
    run after the init window, up to :data:`MAX_MEMBERS` members."""
    from nnfmu.training.horizons import validation_trajectories

    if "test" not in dataset.splits:
        return 0.0
    valid, _ = validation_trajectories(dataset, cfg)
    return MAX_MEMBERS * 2.0 * (2 if init_window > 1 else 1) * dataset.test.n_samples / valid.n_samples


def _select_seconds(trials: Trials, test_runs: float, budget: float) -> float:
    """The seconds kept for the selection and the test scores: measured on the validation free runs of the
    :data:`MAX_CANDIDATES` best trials so far, or :data:`SELECT_SHARE` of the budget before any epoch."""
    if not trials.valid_s:
        return SELECT_SHARE * budget
    best = sorted(trials.scores, key=trials.scores.get)[:MAX_CANDIDATES]
    one = max(trials.valid_s[i] for i in best)
    return min(SELECT_SHARE * budget, max(MIN_SELECT_S, SELECT_SAFETY * one * (SELECT_RUNS + test_runs)))


def _usage(rows: list, cores: int, wall_s: float, trials: Trials) -> dict:
    """How much of the CPU the trials used: their CPU seconds over ``cores * wall_s``, and what else held the cores.

    ``workers_cpu_s``: the workers' whole CPU time (the trials', their start and imports); ``waited_s``: the
    seconds the workers were ready to run while other processes held the cores; ``trials_s``: the seconds the
    trials ran (the rest of ``wall_s``: the selection and the test scores); ``load``: the 5-minute load average."""
    cpu = float(sum(r["cpu_s"] or 0.0 for r in rows))
    load = os.getloadavg()[1] if hasattr(os, "getloadavg") else None
    workers = list(trials.workers.values())
    return {"cpu_s": cpu, "cores": cores, "wall_s": wall_s, "cpu_share": cpu / (cores * max(wall_s, 1e-9)),
            "trials_s": trials.seconds, "workers_cpu_s": sum(c for c, _ in workers) if workers else None,
            "waited_s": sum(w for _, w in workers) if workers else None, "load": load}


def _stalled(found: tuple, rows: list, points: tuple, seeds: int, trial_minutes: float) -> str:
    """Why the best validation score stopped falling in the first half of the trials' time, or "" if it did not.

    ``points``: (the space's points started, all of them); ``seeds``: the trials that were further seeds."""
    if not found or found[-1][0] >= 0.5 * trial_minutes:
        return ""
    after = [r for r in rows if r["trial"] > found[-1][1]]
    halved = sum(r["stopped"] for r in after)
    if not after:
        return (f"the best validation NRMSE last fell at {found[-1][0]:.1f} of {trial_minutes:.1f} minutes: the trials "
                "still training then did not improve on it, and no later trial started")
    started, n_points = points
    tried = (f"every one of the space's {n_points} points was tried and " if started == n_points else
             f"{started} of the space's {n_points} points were tried and ")
    more = f", {seeds} of them the best points again with further seeds" if seeds else ""
    return (f"the best validation NRMSE last fell at {found[-1][0]:.1f} of {trial_minutes:.1f} minutes: {tried}none "
            f"of the {len(after)} trials after trial {found[-1][1]} beat it on validation ({halved} stopped by "
            f"successive halving{more})")


def _resolved(dataset: Dataset, cfg: TrainConfig) -> TrainConfig:
    """``cfg`` with ``valid_horizon`` 'auto' decided here, where the test split (dropped in the trials) is known."""
    from nnfmu.training.horizons import validation_trajectories

    if cfg.valid_horizon != "auto":
        return cfg
    valid, _ = validation_trajectories(dataset, cfg)
    return cfg.replace(valid_horizon="joined" if valid.n_traj < dataset.valid.n_traj else "split")


def _steps_per_epoch(ds: Dataset, cfg: TrainConfig) -> int:
    lengths = [int(sum(ds.train.lengths))] if cfg.join else [int(n) for n in ds.train.lengths]
    pieces = sum(n // cfg.truncate for n in lengths) if cfg.truncate else len(lengths)
    return max(1, math.ceil(max(pieces, 1) / cfg.batch_size))


def _row(i: int, point: dict, folder: Path, record: dict, stopped: bool) -> dict:
    """The table row of trial ``i``: its knobs, and what its checkpoint and its worker's ``record`` say (an empty
    record: the search was stopped before the trial ended)."""
    from nnfmu.errors import CheckpointError
    from nnfmu.models import load_checkpoint

    cpu = record.get("cpu_s", record.get("last", {}).get("cpu_s"))
    row = {"trial": i, **point, "epochs": 0, "best_valid_nrmse": None, "stopped": stopped, "cpu_s": cpu,
           "status": record.get("status", "ended when the search was stopped"), "error": record.get("error")}
    ckpt = folder / f"trial-{i}.pt"
    try:
        summary = load_checkpoint(ckpt)["summary"] if ckpt.is_file() else {}
    except CheckpointError:
        summary = {}
    if summary.get("epochs_run", 0) >= 1 and math.isfinite(summary["best_valid_nrmse"]):
        row.update(epochs=int(summary["epochs_run"]), best_valid_nrmse=float(summary["best_valid_nrmse"]))
    if stopped:
        row["status"] = "stopped by successive halving"
    elif row["status"] == "stopped":
        row["status"] = "stopped: the search's time was up"
    return row


def _keep(rows: list, folder: Path, dataset: Dataset, out: Path, deadline: float | None) -> TimeSearchResult | None:
    """Select the kept model (module docstring) and write it, with its test scores, atomically to ``out``.

    ``deadline``: the :func:`time.monotonic` time by which the test scores are written (None: keep the best trial
    alone, without a selection: the search was stopped). None when no trial finished an epoch.
    """
    import io

    import torch

    from nnfmu.atomic import write_atomic
    from nnfmu.models import load_checkpoint, model_from_checkpoint
    from nnfmu.models.checkpoint import state_snapshot
    from nnfmu.training import dataset_meta
    from nnfmu.training.trainer import _test_scores

    scored = sorted((r for r in rows if r["best_valid_nrmse"] is not None),
                    key=lambda r: (r["best_valid_nrmse"], r["trial"]))
    if not scored:
        return None
    best = scored[0]["trial"]
    ckpt = load_checkpoint(folder / f"trial-{best}.pt")
    model, members, scores, why = model_from_checkpoint(ckpt), (best,), (scored[0]["best_valid_nrmse"],), ""
    if deadline is not None:
        model, members, scores, why = _select(scored, folder, dataset, ckpt, model, deadline)
        if len(members) == 1:  # one trial alone: its checkpoint, and its score as its training kept it, the table's
            ckpt = ckpt if members[0] == best else load_checkpoint(folder / f"trial-{members[0]}.pt")
            scores = (next(r["best_valid_nrmse"] for r in scored if r["trial"] == members[0]),)
    test, window = _test_scores(model, dataset)
    search = {"trials": len(rows), "best": best, "kept": members[0], "members": list(members),
              "member_valid_nrmse": list(scores), "selection": why}
    if len(members) > 1:
        summary = {"best_valid_nrmse": scores[-1], "stop_reason": "search", "search": search,
                   "notes": [f"an ensemble of trials {', '.join(map(str, members))} of the time-budget search, "
                             f"chosen greedily on validation ({why})"]}
        meta = {**ckpt["meta"], "name": dataset_meta(dataset, "ensemble")["name"]}  # the FMU's model name
        ckpt = {**ckpt, "meta": meta, "model_config": model.config.to_dict(), "state_dict": state_snapshot(model),
                "history": [], "best_epoch": None, "resume": None, "summary": summary}
    else:
        ckpt["summary"].update(search=search)
    ckpt["summary"].update(test_nrmse=None if test is None else test.mean,
                           test_nrmse_window=None if window is None else window.mean)
    buffer = io.BytesIO()
    torch.save(ckpt, buffer)
    write_atomic(out, lambda tmp: tmp.write_bytes(buffer.getbuffer()))
    return TimeSearchResult(best=best, best_valid_nrmse=scores[-1], out=out, model_config=ckpt["model_config"],
                            train_config=ckpt["train_config"], test=test, test_window=window, members=members,
                            member_scores=scores, selection=why)


def _select(scored: list, folder: Path, dataset: Dataset, ckpt: dict, model, deadline: float) -> tuple:
    """``(model, member trials, validation NRMSE after each, why it ended)``: the seeds of the best point, or the
    greedy selection over the best trials.

    The best point (:func:`_best_point`): the one whose seeds have the lowest mean validation NRMSE, among points
    with :data:`MIN_SEEDS` seeds or more; its seeds (up to :data:`MAX_MEMBERS`, the best first) are joined greedily,
    each only where it lowers the validation NRMSE by 1 %, and the ensemble is kept where it is at or below trial 0,
    the defaults, on validation. Otherwise (no such point, as in a search too short to train further seeds): the
    best trial and the next best that improved on their start, up to :data:`MAX_CANDIDATES`, joined greedily. The
    selection stops early enough to score the kept model on the test split by ``deadline``.
    """
    point = _best_point(scored)
    if point is not None:
        trials, models = _candidates(point[1], folder, MAX_MEMBERS)
        if len(trials) >= MIN_SEEDS:
            kept = _greedy(trials, models, dataset, ckpt, deadline)
            zero = next((r["best_valid_nrmse"] for r in scored if r["trial"] == 0), math.inf)
            if kept[2][-1] <= zero:
                knobs = label({k: point[1][0][k] for k in KNOBS})
                return kept[:3] + (f"the seeds of the point best on their mean validation NRMSE ({knobs}: "
                                   f"{point[0]:.4f} over {len(point[1])} seeds), joined greedily: {kept[3]}",)
    trials, models = _candidates(scored, folder, MAX_CANDIDATES, first=model)
    if len(models) == 1:
        return model, tuple(trials), (scored[0]["best_valid_nrmse"],), "no other trial improved on its start"
    kept = _greedy(trials, models, dataset, ckpt, deadline)
    return kept[:3] + (f"the best trials joined greedily from the best: {kept[3]}",)


def _best_point(scored: list) -> tuple | None:
    """``(mean validation NRMSE, its trials' rows best first)`` of the point whose seeds score best on average.

    A point's seeds: its trials (the same knobs, :data:`~nnfmu.study.time_space.KNOBS`) that finished an epoch and
    that successive halving did not stop; a point needs :data:`MIN_SEEDS` of them (the search trains further seeds
    of its best points once every point has started). The mean, not the best seed, ranks the points: a search
    that keeps the best of many seeds keeps the luckiest on validation (docs/accuracy.md, "Which trials a search
    keeps"). None when no point has enough seeds.
    """
    seeds: dict = {}
    for r in scored:
        if not r["stopped"]:
            seeds.setdefault(point_key(r), []).append(r)
    means = [(sum(r["best_valid_nrmse"] for r in rows) / len(rows), rows) for rows in seeds.values()
             if len(rows) >= MIN_SEEDS]
    if not means:
        return None
    mean, rows = min(means, key=lambda m: (m[0], m[1][0]["trial"]))
    return mean, sorted(rows, key=lambda r: (r["best_valid_nrmse"], r["trial"]))


def _candidates(rows: list, folder: Path, limit: int, first=None) -> tuple[list, list]:
    """``(trials, models)``: of ``rows`` (best first), up to ``limit`` that improved on their start (best epoch
    > 0); ``first``: ``rows[0]``'s model, already loaded, taken whatever its best epoch."""
    from nnfmu.models import load_checkpoint, model_from_checkpoint

    trials, models = ([rows[0]["trial"]], [first]) if first is not None else ([], [])
    for r in rows[len(trials):]:
        if len(trials) == limit:
            break
        ckpt = load_checkpoint(folder / f"trial-{r['trial']}.pt")
        if (ckpt.get("best_epoch") or 0) > 0:
            trials.append(r["trial"])
            models.append(model_from_checkpoint(ckpt))
    return trials, models


def _greedy(trials: list, models: list, dataset: Dataset, ckpt: dict, deadline: float) -> tuple:
    """The greedy ensemble of ``models`` (``trials``' networks, best first) on the validation free runs."""
    from nnfmu.training.ensemble_select import select_ensemble
    from nnfmu.training.horizons import validation_trajectories

    valid, _ = validation_trajectories(dataset, TrainConfig.from_dict(ckpt["train_config"]))
    test_share = dataset.test.n_samples / valid.n_samples if "test" in dataset.splits else 0.0
    context = models[0].config.init_window
    # then the test's free runs (one; two with an init window), in float64: about twice a validation run's cost
    selection = select_ensemble(models, valid, context=context, deadline=deadline,
                                after=2.0 * (2 if context > 1 else 1) * test_share)
    return (selection.model, tuple(trials[i] for i in selection.chosen), tuple(selection.scores),
            selection.stopped)
