"""``nnfmu train --max-minutes N`` without ``--epochs``: the budget spent on a small early-stopping search.

:func:`search_for` trains the points of :mod:`nnfmu.study.time_space` (trial 0 the plain defaults) in a local
Ray instance, one CPU and one torch thread per trial, as many at once as there are CPUs. Every trial is
:func:`nnfmu.training.train` with its own ``max_minutes`` cap and reports its validation free-run NRMSE after
every epoch; Ray Tune's ASHA scheduler stops the trials that trail the others at the same epoch (grace
period: :data:`GRACE_STEPS` optimiser steps, at least 3 epochs). The whole search ends within the budget:

- the budget counts from the call, or from ``since`` (``nnfmu train``: from the command's start); Ray's start
  (10-30 s on 2 busy cores) is part of it. :data:`END_RESERVE` of it (at least :data:`MIN_RESERVE_S`) is
  kept for the last epochs to finish, Ray's shutdown and the copy of the best;
- ``clamp(cpus * time left / TRIAL_MINUTES, cpus, MAX_TRIALS)`` trials are planned, each capped at
  ``CAP_SHARE x`` its fair share of the time (ASHA ends most of them early), and never past the end;
  a core whose trial ended takes the next point, of up to :data:`MAX_POINTS`, so that the budget is spent
  when ASHA ends the trials faster than planned;
- no trial starts once less than a quarter of a cap (or :data:`MIN_TRIAL_S`) is left; a trial stops after
  an epoch when the next would end past the end; Tune's own time budget stops whatever still runs then.

The trials validate on the validation split only (the test split stays in the driver). The trial with the
lowest best validation NRMSE kept in its checkpoint starts a greedy ensemble selection on validation
(:func:`nnfmu.training.ensemble_select.select_ensemble`) over the :data:`MAX_CANDIDATES` best trials that
improved on their start: another trial joins as a member of one model (the mean output fed back) only if it
lowers the validation free-run NRMSE by 1 % or more, up to 4 members. :data:`SELECT_SHARE` of the budget is
kept for it, ending early enough to score the kept model on the test split in time. The kept model (one
trial's network, or the mixed ensemble of several), with its test scores added, is written atomically to
``out``. Nothing is written to ``out`` unless a trial finished an epoch.
"""

from __future__ import annotations

import contextlib
import dataclasses
import json
import logging
import math
import os
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path
from unittest import mock

from nnfmu.atomic import write_text_atomic
from nnfmu.data import Dataset
from nnfmu.errors import ConfigError, NnfmuError, TrainingError
from nnfmu.study.ray_connect import ray_session, require_ray
from nnfmu.study.time_space import trial_configs, trial_points
from nnfmu.study.tune import METRIC, _finite
from nnfmu.training import TrainConfig
from nnfmu.training.plan import PATIENCE_STEPS
from nnfmu.training.resources import usable_cores

END_RESERVE = 0.05  # of the budget, at least MIN_RESERVE_S
MIN_RESERVE_S = 5.0
TRIAL_MINUTES = 0.5  # planned CPU-minutes per trial
CAP_SHARE = 2.5
MAX_TRIALS = 24  # planned: what sets each trial's cap
MAX_POINTS = 4 * MAX_TRIALS  # run while time is left (the robot's 24 planned trials ended in 435 of its 600 s)
MIN_TRIAL_S = 5.0
GRACE_STEPS = 20
SELECT_SHARE = 0.1  # of the budget, kept for the ensemble selection after the trials
MAX_CANDIDATES = 6  # the best trials on validation that the selection tries
THREAD_TIMEOUT_S = 60


@dataclass(frozen=True)
class TimeSearchResult:
    """The search: one row per trial (``rows``), the kept trial's index and checkpoint, the time spent.

    A row: ``trial``, the knobs (``arch``, ``hidden``, ``lr``, ``feedback_noise``, ``truncate``), ``epochs``
    (run), ``best_valid_nrmse`` (kept in its checkpoint; None if it never finished an epoch), ``stopped``
    (by ASHA), ``cpu_s`` (CPU seconds of its worker), ``status`` (how it ended) and ``error``. ``best``: the
    trial best on validation; ``members``: the trials of the kept model (``(best,)``, or the ensemble's, in the
    order the selection added them) and ``member_scores`` the validation NRMSE after each addition;
    ``best_valid_nrmse``: the kept model's. ``test`` and ``test_window``: the kept model's free-run test scores
    (:class:`~nnfmu.metrics.NrmseResult` or None), as :class:`~nnfmu.training.TrainResult` has them;
    ``model_config`` and ``train_config``: the kept model's, as its checkpoint holds them (dicts).
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


def search_for(dataset: Dataset, minutes: float, *, model_config, train_config: TrainConfig, linear=None,
               out, given=(), seed: int = 0, progress: bool = True, cpus: int | None = None,
               since: float | None = None) -> TimeSearchResult:
    """Spend ``minutes`` on the search (module docstring); the best trial's checkpoint is written to ``out``.

    ``dataset`` has its validation split; ``model_config`` is the base network (its ``arch`` is trial 0's and is
    searched unless ``"arch"`` is in ``given``; None: a GRU on the linear path of ``linear``), ``train_config``
    the planned training (``max_minutes`` is not used: ``minutes`` is the budget), ``linear`` the linear model
    of the linear path (or None), ``given`` the names of the options the user gave (kept as given). Ctrl-C,
    SIGTERM or an error during the search still writes the best finished trial to ``out``, then goes on.
    ``since``: the :func:`time.monotonic` time the budget counts from (default: now; the CLI passes its start).
    """
    started = time.monotonic() if since is None else since
    _, tune = require_ray()
    from nnfmu.study.time_ray import Asha, Echo, Points

    if dataset.valid is None:
        raise ConfigError("the time search needs a dataset with its validation split (carve it first)")
    if model_config is None:
        from nnfmu.models import ModelConfig

        model_config = ModelConfig(arch="gru", n_u=dataset.n_u, n_y=dataset.n_y,
                                   linear_order=0 if linear is None else linear.n_x)
    if not (isinstance(minutes, (int, float)) and minutes > 0):
        raise ConfigError(f"the search budget must be > 0 minutes, got {minutes!r}")
    cpus = max(1, int(cpus or usable_cores()))
    out, given = Path(out), set(given)
    reserve = max(MIN_RESERVE_S, END_RESERVE * 60.0 * minutes)
    final = started + 60.0 * minutes
    end = final - reserve - SELECT_SHARE * 60.0 * minutes
    train_config = _resolved(dataset, train_config)
    trials_ds = dataset.replace(splits={k: v for k, v in dataset.splits.items() if k != "test"})
    steps = _steps_per_epoch(trials_ds, train_config)
    grace = max(3, math.ceil(GRACE_STEPS / steps))
    if train_config.patience == 0:  # the budget alone: a trial that stalls ends, leaving its core to the next
        train_config = train_config.replace(patience=max(2 * grace, math.ceil(PATIENCE_STEPS / steps)))
    with tempfile.TemporaryDirectory(prefix="nnfmu-search-") as tmp, _quiet_ray(), ray_session(None, cpus, 0):
        left = end - time.monotonic()
        planned = min(MAX_TRIALS, max(cpus, cpus * left / (60.0 * TRIAL_MINUTES)))
        cap = max(MIN_TRIAL_S, min(left, CAP_SHARE * cpus * left / planned))
        # more points than planned: a core whose trial ended early takes the next, while time is left
        points = trial_points(model_config, train_config, given, MAX_POINTS, seed,
                              int(trials_ds.train.lengths.max()))
        wall_end = time.time() + (end - time.monotonic())
        job = {"points": points, "model_config": model_config.to_dict(), "train_config": train_config.to_dict(),
               "given": sorted(given), "folder": tmp, "cap_s": cap, "end": wall_end}
        scheduler = Asha(time_attr="epoch", max_t=10 ** 6, grace_period=grace, reduction_factor=2)
        searcher = Points(len(points), end, max(MIN_TRIAL_S, cap / 4))
        trainable = tune.with_resources(tune.with_parameters(_trial, dataset=trials_ds, linear=linear, job=job),
                                        {"cpu": 1, "gpu": 0})
        run_config = tune.RunConfig(name="nnfmu-time-search", verbose=0, storage_path=str(Path(tmp) / "ray"),
                                    callbacks=[Echo(points, scheduler)] if progress else None)
        tune_config = tune.TuneConfig(metric=METRIC, mode="min", scheduler=scheduler, search_alg=searcher,
                                      num_samples=len(points), max_concurrent_trials=cpus, reuse_actors=False,
                                      time_budget_s=max(1.0, end - time.monotonic() + reserve / 2))
        stopped_by = None
        try:
            tune.Tuner(trainable, run_config=run_config, tune_config=tune_config).fit()
        except BaseException as exc:  # Ctrl-C, SIGTERM or a failure: the best finished trial is still kept
            stopped_by = exc
        rows = [_row(i, p, Path(tmp), i in scheduler.stopped_points, scheduler.last.get(i, {}))
                for i, p in enumerate(points) if i < searcher.next]
        kept = _keep(rows, Path(tmp), dataset, out, None if stopped_by is not None else final - reserve / 2)
        if stopped_by is not None:
            if kept is not None:
                print(f"search stopped ({type(stopped_by).__name__}): the best trial so far, {kept.best}, "
                      f"validation free-run NRMSE {kept.best_valid_nrmse:.4f}, is kept in {out}", flush=True)
            raise stopped_by
    seconds = time.monotonic() - started
    if kept is None:
        return TimeSearchResult(rows, seconds=seconds)
    return dataclasses.replace(kept, rows=rows, seconds=seconds)


@contextlib.contextmanager
def _quiet_ray():
    """Ray's own tables and INFO lines off (the search prints one line per trial, and its table); Ctrl-C raises."""
    loggers = {logging.getLogger(name): level for name, level in
               (("ray", logging.WARNING), ("ray.tune", logging.ERROR), ("ray.train", logging.ERROR))}
    levels = [lg.level for lg in loggers]
    for lg, level in loggers.items():
        lg.setLevel(level)
    try:
        # Ctrl-C raises KeyboardInterrupt here (Ray Tune's own handler would end the search quietly); a worker
        # whose trial ASHA stopped waits for it to write its checkpoint (default 2 s); the workers inherit this
        # environment. Every trial gets a fresh worker (reuse_actors=False): with Ray 2.60 a reused worker whose
        # stopped trial had not ended failed ("reuse requires reset_config()") and its next trial then held the
        # core, with no epoch, until the search's time was up (2 of the robot's 5 trials)
        with mock.patch.dict(os.environ, {"RAY_AIR_NEW_OUTPUT": "0", "TUNE_DISABLE_SIGINT_HANDLER": "1",
                                          "TUNE_FUNCTION_THREAD_TIMEOUT_S": str(THREAD_TIMEOUT_S)}):
            yield
    finally:
        for lg, level in zip(loggers, levels):
            lg.setLevel(level)


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


def _trial(config: dict, dataset: Dataset | None = None, linear=None, job: dict | None = None) -> None:
    """One trial (in a Ray worker): train the point until its cap, the end of the search, or ASHA stops it."""
    from ray import tune

    from nnfmu.models import ModelConfig
    from nnfmu.training import StopTraining, train

    i, folder = int(config["trial"]), Path(job["folder"])
    seconds = min(job["cap_s"], job["end"] - time.time())
    row = {"status": "not started: the search's time was up", "error": None, "cpu_s": 0.0}
    if seconds >= 1.0:
        model_config, train_config = trial_configs(job["points"][i], ModelConfig.from_dict(job["model_config"]),
                                                   TrainConfig.from_dict(job["train_config"]), set(job["given"]))
        train_config = train_config.replace(max_minutes=seconds / 60.0)
        cpu0, stopped = time.process_time(), []

        def report(epoch: int, metrics: dict) -> None:
            try:
                tune.report({"epoch": epoch, "valid_nrmse": _finite(metrics["valid_nrmse"]),
                             METRIC: _finite(metrics["best_valid_nrmse"]), "cpu_s": time.process_time() - cpu0})
            except SystemExit:  # Ray stops this trial: keep what it has, in its checkpoint
                stopped.append(epoch)
                raise StopTraining from None
            if time.time() + metrics["seconds"] > job["end"]:  # another epoch would end past the search's end
                raise StopTraining

        try:
            result = train(dataset, model_config, train_config, out=folder / f"trial-{i}.pt", callback=report,
                           device="cpu", threads=1, linear=linear)
            row["status"] = ("stopped by Ray" if stopped else "time-budget" if result.stop_reason == "callback"
                             else result.stop_reason)
        except TrainingError as exc:  # a diverging point is a bad score, not a failed search
            row.update(status="diverged", error=str(exc).split(";")[0])
        except NnfmuError as exc:
            row.update(status="failed", error=str(exc))
        row["cpu_s"] = time.process_time() - cpu0
    write_text_atomic(folder / f"trial-{i}.json", json.dumps(row))  # a worker ended mid-write leaves no half record


def _row(i: int, point: dict, folder: Path, stopped: bool, last: dict) -> dict:
    """The table row of trial ``i``: its knobs, and what its checkpoint, its own record and its ``last`` report say."""
    from nnfmu.errors import CheckpointError
    from nnfmu.models import load_checkpoint

    row = {"trial": i, **point, "epochs": 0, "best_valid_nrmse": None, "stopped": stopped, "cpu_s": last.get("cpu_s"),
           "status": "ended by Ray before it finished (the search's time was up)", "error": None}
    record = folder / f"trial-{i}.json"
    with contextlib.suppress(OSError, ValueError):  # none, or unreadable: the row says Ray ended the trial
        row.update(json.loads(record.read_text()))
    ckpt = folder / f"trial-{i}.pt"
    try:
        summary = load_checkpoint(ckpt)["summary"] if ckpt.is_file() else {}
    except CheckpointError:
        summary = {}
    if summary.get("epochs_run", 0) >= 1 and math.isfinite(summary["best_valid_nrmse"]):
        row.update(epochs=int(summary["epochs_run"]), best_valid_nrmse=float(summary["best_valid_nrmse"]))
    if stopped:
        row["status"] = "stopped by ASHA"
    elif row["status"] == "stopped by Ray":
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
        if len(members) == 1:  # the trial alone: its score as its training kept it, the table's
            scores = (scored[0]["best_valid_nrmse"],)
    test, window = _test_scores(model, dataset)
    search = {"trials": len(rows), "kept": best, "members": list(members), "member_valid_nrmse": list(scores),
              "selection": why}
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
    """``(model, member trials, validation NRMSE after each, why it ended)`` of the greedy selection.

    The candidates: the best trial and the next best that improved on their start (best epoch > 0), up to
    :data:`MAX_CANDIDATES`. The selection stops early enough to score the kept model on the test split by
    ``deadline``.
    """
    from nnfmu.models import load_checkpoint, model_from_checkpoint
    from nnfmu.training.ensemble_select import select_ensemble
    from nnfmu.training.horizons import validation_trajectories

    trials, models = [scored[0]["trial"]], [model]
    for r in scored[1:]:
        if len(trials) == MAX_CANDIDATES:
            break
        other = load_checkpoint(folder / f"trial-{r['trial']}.pt")
        if (other.get("best_epoch") or 0) > 0:
            trials.append(r["trial"])
            models.append(model_from_checkpoint(other))
    if len(models) == 1:
        return model, tuple(trials), (scored[0]["best_valid_nrmse"],), "no other trial improved on its start"
    valid, _ = validation_trajectories(dataset, TrainConfig.from_dict(ckpt["train_config"]))
    test_share = dataset.test.n_samples / valid.n_samples if "test" in dataset.splits else 0.0
    # then the test's free runs (one; two with an init window), in float64: about twice a validation run's cost
    selection = select_ensemble(models, valid, context=model.config.init_window, deadline=deadline,
                                after=2.0 * (2 if model.config.init_window > 1 else 1) * test_share)
    return (selection.model, tuple(trials[i] for i in selection.chosen), tuple(selection.scores),
            selection.stopped)
