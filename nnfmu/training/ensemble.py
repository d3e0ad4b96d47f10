"""``train_seeds``: the same network trained from K seeds, then the best on validation or their ensemble kept.

On small data a seed moves the result more than a training strategy does (issue 11: 0.199 against
0.286 for one GRU on one plant), so one run says little. ``train_seeds`` trains K seeds (in
parallel processes where there are cores), each a normal resumable :func:`train` into
``<out>.seeds/seed-<s>.pt``, and writes to ``out`` either

- ``keep="best"``: the seed with the lowest validation NRMSE, or
- ``keep="ensemble"``: all K as one :class:`~nnfmu.models.EnsembleStepModel` (their mean output
  fed back as the one prediction), which exports as one FMU.
- ``keep="select"``: the greedy selection on validation (:mod:`nnfmu.training.ensemble_select`): from
  the best seed, another joins only if it lowers the validation NRMSE by 1 % or more, so the kept model
  is the best seed alone unless averaging helps on validation.

The result lists every seed's validation and test scores, so the spread over seeds is reported
next to the kept model's. The validation split is fixed once (carved with the base seed), so
every seed is trained and chosen on the same data. With ``refit_on``, the kept seeds then train once
more on the training and validation data together, and the kept model is made of those
(:mod:`nnfmu.training.refit`).
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from functools import partial
from pathlib import Path

import numpy as np

from nnfmu.data import Dataset, Trajectories
from nnfmu.errors import ConfigError
from nnfmu.metrics import NrmseResult
from nnfmu.models import ModelConfig, StepModel, load_checkpoint, load_model, save_checkpoint
from nnfmu.training.config import TrainConfig
from nnfmu.training.ensemble_select import ensemble_score, select_ensemble
from nnfmu.training.evaluate import free_run_nrmse
from nnfmu.training.horizons import validation_trajectories
from nnfmu.training.refit import refit_kept
from nnfmu.training.seed_runs import (error_file, further_seeds, history_seconds, planned_jobs, train_members,
                                      training_seconds)
from nnfmu.training.trainer import _as_train_config, prepare_dataset

KEEP = ("best", "ensemble", "select")


@dataclass(frozen=True)
class SeedsResult:
    """What :func:`train_seeds` returns.

    Attributes
    ----------
    model : StepModel
        The kept model (the best seed, or the ensemble), in eval mode, as saved at ``checkpoint``.
    keep : {'best', 'ensemble', 'select'}
    valid_nrmse : float
        The kept model's validation free-run NRMSE (the trainer's protocol).
    test, test_window : NrmseResult or None
        The kept model's float64 free-run test scores (from y0; after the init window).
    seeds : list of dict
        Per seed: ``seed``, ``checkpoint``, ``best_valid_nrmse``, ``test_nrmse``, ``test_nrmse_window``,
        ``best_epoch``, ``epochs_run``, ``stop_reason``, ``error`` (why a failed seed stopped; its best
        weights before the failure are used).
    checkpoint : Path
    notes : list of str
    refit : dict or None
        With a refit (``refit_on``): the seeds refitted, their epochs and seconds, the samples they trained on, and
        the chosen model's test scores before the refit (reported only). ``valid_nrmse`` is the score the kept
        model was chosen by, before the refit: the validation data train the refitted weights.
    """

    model: StepModel
    keep: str
    valid_nrmse: float
    test: NrmseResult | None
    test_window: NrmseResult | None
    seeds: list
    checkpoint: Path
    notes: list = field(default_factory=list)
    refit: dict | None = None

    @property
    def test_nrmse(self) -> float | None:
        return None if self.test is None else self.test.mean

    def spread(self, key: str = "test_nrmse") -> dict:
        """``{mean, min, max}`` of a per-seed score over the seeds (None values left out)."""
        values = [s[key] for s in self.seeds if s.get(key) is not None]
        if not values:
            return {"mean": None, "min": None, "max": None}
        return {"mean": float(np.mean(values)), "min": float(min(values)), "max": float(max(values))}


def seeds_folder(out: Path) -> Path:
    """The folder of the member checkpoints of ``out``: ``<out stem>.seeds/`` beside it."""
    return out.parent / f"{out.stem}.seeds"


def seed_paths(out: Path, seeds: list[int]) -> list[Path]:
    """Where the member checkpoints of ``out`` live: ``<out stem>.seeds/seed-<s>.pt``."""
    return [seeds_folder(out) / f"seed-{s}.pt" for s in seeds]


def _trained(rows: list) -> list[int]:
    """The indices of the seeds that improved on their start (best epoch > 0)."""
    return [i for i, r in enumerate(rows) if (r["best_epoch"] or 0) > 0]


def train_seeds(dataset: Dataset, model_config: ModelConfig, train_config: TrainConfig | None = None, *,
                seeds: int = 3, keep: str = "select", out: str | os.PathLike, jobs: int | None = None,
                progress: bool = False, device="auto", threads: int | None = None, linear=None,
                overwrite: bool = False, refit_on: Trajectories | None = None, more_within: float | None = None,
                most: int | None = None) -> SeedsResult:
    """Train ``model_config`` from ``seeds`` seeds (``train_config.seed``, +1, ...) and keep the best or the ensemble.

    Parameters
    ----------
    dataset : Dataset
    model_config : ModelConfig
        One network (``members = 1``).
    train_config : TrainConfig, optional
    seeds : int
        K >= 2 seeds.
    keep : {'select', 'best', 'ensemble'}
        See the module docstring (default 'select': chosen on validation alone).
    out : path
        The kept model's checkpoint; members go to ``<stem>.seeds/``. Finished members are not
        trained again and unfinished ones resume, so a stopped call continues where it was.
    jobs : int, optional
        Processes training at once (default: the cores this process may use, at most K).
    progress : bool
        Progress bars: every seed's one after the other with one job, else the first seed's.
    device, threads, linear :
        As in :func:`train`, for every seed (a linear path's start is identified once, here, when not given).
    overwrite : bool
        Delete a member checkpoint that holds a training of other settings and train it anew (``nnfmu train
        --force``); False: a ConfigError says so.
    refit_on : Trajectories, optional
        The training and validation data together (:func:`nnfmu.training.refit.training_and_validation` of the
        dataset as loaded). After choosing, each kept seed trains once more on them, from its seed, for the epochs
        it kept, into ``<stem>.seeds/refit-<s>.pt``, and the kept model is made of those (:mod:`nnfmu.training.refit`).
        None: no refit.
    more_within, most : float (seconds), int, optional
        With ``more_within``: after the K seeds, further waves of as many seeds as train at once (``jobs``) train
        while the waves so far leave room for one more within ``more_within`` wall seconds, up to ``most`` seeds
        in all (:func:`~nnfmu.training.seed_runs.further_seeds`); a note says how many and why they ended. The
        choice is made over every seed trained. None: the K seeds only.
    """
    if keep not in KEEP:
        raise ConfigError(f"unknown keep {keep!r}; choose one of {', '.join(KEEP)}")
    if isinstance(seeds, bool) or not isinstance(seeds, int) or seeds < 2:
        raise ConfigError(f"seeds must be an integer >= 2 (one seed is a plain train), got {seeds!r}")
    if not isinstance(model_config, ModelConfig) or model_config.members != 1:
        raise ConfigError("train_seeds trains one network per seed: pass a ModelConfig with members=1")
    cfg = _as_train_config(train_config)
    dataset, notes = prepare_dataset(dataset, cfg)  # one validation split for every seed
    out = Path(out)
    seed_list = [cfg.seed + i for i in range(seeds)]
    seeds_folder(out).mkdir(parents=True, exist_ok=True)
    n_jobs = planned_jobs(jobs, seeds)
    if model_config.linear_order and linear is None:
        from nnfmu.linear import LinearConfig, identify_linear

        linear = identify_linear(dataset, LinearConfig(order=model_config.linear_order))

    def wave(wave_seeds: list) -> None:  # side by side, the first seed of the wave shows its progress
        work = [(dataset, model_config, cfg.replace(seed=s), p, progress and (n_jobs == 1 or i == 0))
                for i, (s, p) in enumerate(zip(wave_seeds, seed_paths(out, wave_seeds)))]
        train_members(work, n_jobs, device=device, threads=threads, linear=linear, overwrite=overwrite, what="seeds")

    wave(seed_list)
    if more_within is not None:
        seed_list, waves_note = _further_waves(wave, seed_list, out, n_jobs, most or seeds, more_within)
        notes = notes + [waves_note]
    paths = seed_paths(out, seed_list)
    refit = None if refit_on is None else partial(
        refit_kept, chosen_on=dataset, whole=refit_on, model_config=model_config, cfg=cfg, folder=paths[0].parent,
        jobs=jobs, progress=progress, device=device, threads=threads, linear=linear, overwrite=overwrite)
    return _keep(dataset, cfg, keep, seed_list, paths, out, notes, refit)


def _further_waves(wave, seed_list: list, out: Path, per_wave: int, most: int, within: float) -> tuple[list, str]:
    """Train further waves of seeds (``wave(seeds)``) while :func:`~nnfmu.training.seed_runs.further_seeds` allows:
    ``(every seed trained, a note on the waves)``."""
    walls = [max(training_seconds(p) for p in seed_paths(out, seed_list))]  # each wave's, read once it is trained
    while True:
        k, why = further_seeds(walls, per_wave, len(seed_list), most, within)
        if not k:
            return seed_list, (f"trained {len(seed_list)} seeds in {len(walls)} wave(s) of up to {per_wave} side by "
                               f"side, {sum(walls) / 60:.1f} minutes of training; no further wave: {why}")
        more = [seed_list[-1] + 1 + i for i in range(k)]
        wave(more)
        walls.append(max(training_seconds(p) for p in seed_paths(out, more)))
        seed_list = seed_list + more


def _seed_row(seed: int, path: Path) -> dict:
    ckpt = load_checkpoint(path)
    summary = ckpt.get("summary") or {}
    return {"seed": seed, "checkpoint": str(path), "best_valid_nrmse": summary.get("best_valid_nrmse"),
            "test_nrmse": summary.get("test_nrmse"), "test_nrmse_window": summary.get("test_nrmse_window"),
            "best_epoch": ckpt.get("best_epoch"), "epochs_run": summary.get("epochs_run"),
            "stop_reason": summary.get("stop_reason") or "failed",
            "seconds": history_seconds(ckpt),
            "start_valid_nrmse": next((h.get("valid_nrmse") for h in ckpt.get("history", []) if h.get("epoch") == 0),
                                      None),
            "error": error_file(path).read_text().strip() if error_file(path).exists() else None}


def _ensemble_of_trained(models: list, rows: list, valid, n: int) -> tuple[StepModel, float, list, list]:
    """The ensemble of the seeds that improved on their start (best epoch > 0), its validation NRMSE, notes, and
    the indices of the seeds kept.

    A seed whose best epoch is 0 never trained: averaged in, its untrained output would pull the ensemble back
    towards the start (a random network, or the linear model of a linear path). With fewer than two trained
    seeds, or when the ensemble's validation NRMSE is above the seeds' start (epoch 0: the linear model of a
    linear path), the best seed on validation is kept alone: like one training, the kept model is never worse
    on validation than where training started.
    """
    trained = _trained(rows)
    notes = [f"dropped seed {rows[i]['seed']} from the ensemble: it never improved on its start on validation "
             f"(best epoch 0, validation NRMSE {rows[i]['best_valid_nrmse']:.4f})"
             for i in range(len(rows)) if i not in trained]
    if len(trained) < 2:
        pool = trained or list(range(len(rows)))
        best = min(pool, key=lambda i: rows[i]["best_valid_nrmse"])
        notes.append(f"fewer than two seeds trained: kept seed {rows[best]['seed']} alone instead of an ensemble")
        return models[best], rows[best]["best_valid_nrmse"], notes, [best]
    model, score = ensemble_score([models[i] for i in trained], valid, context=n)
    starts = [rows[i]["start_valid_nrmse"] for i in trained if rows[i].get("start_valid_nrmse") is not None]
    if starts and not score <= min(starts):
        best = min(trained, key=lambda i: rows[i]["best_valid_nrmse"])
        notes.append(f"the ensemble's validation NRMSE {score:.4f} is above the seeds' start ({min(starts):.4f}): "
                     f"kept seed {rows[best]['seed']} alone")
        return models[best], rows[best]["best_valid_nrmse"], notes, [best]
    return model, score, notes, trained


def _selected(models: list, rows: list, valid, n: int) -> tuple[StepModel, float, list, list]:
    """The greedy selection over the seeds that improved on their start (all, if none did), best first."""
    pool = _trained(rows) or list(range(len(rows)))
    pool.sort(key=lambda i: rows[i]["best_valid_nrmse"])
    picked = select_ensemble([models[i] for i in pool], valid, context=n, max_members=len(pool))
    seeds = [rows[pool[c]]["seed"] for c in picked.chosen]
    steps = " -> ".join(f"{v:.4f}" for v in picked.scores)
    what = f"seed {seeds[0]} alone" if len(seeds) == 1 else f"the ensemble of seeds {', '.join(map(str, seeds))}"
    tried = "" if picked.rejected is None else f": the best ensemble tried scored {picked.rejected:.4f}"
    note = f"kept {what} (validation NRMSE {steps}; {picked.stopped}{tried})"
    return picked.model, picked.scores[-1], [note], [pool[c] for c in picked.chosen]


def _chosen(keep: str, models: list, rows: list, valid, n: int) -> tuple[StepModel, float, list, list]:
    """``(kept model, its validation NRMSE, notes, indices of the seeds it holds)`` by the rule ``keep``."""
    if keep == "best":
        best = min(range(len(rows)), key=lambda i: rows[i]["best_valid_nrmse"])
        return models[best], rows[best]["best_valid_nrmse"], [f"kept seed {rows[best]['seed']} (lowest validation "
                                                              "NRMSE)"], [best]
    if keep == "select":
        return _selected(models, rows, valid, n)
    return _ensemble_of_trained(models, rows, valid, n)


def _keep(dataset: Dataset, cfg: TrainConfig, keep: str, seed_list: list, paths: list, out: Path, notes: list,
          refit=None) -> SeedsResult:
    """Choose on validation, refit the kept seeds where ``refit`` (:func:`nnfmu.training.refit.refit_kept` with
    everything but the choice bound) is given, and write the kept model to ``out``."""
    rows = [_seed_row(s, p) for s, p in zip(seed_list, paths)]
    models = [load_model(p) for p in paths]
    valid, valid_notes = validation_trajectories(dataset, cfg)
    n = models[0].config.init_window
    model, valid_nrmse, chosen, kept = _chosen(keep, models, rows, valid, n)
    notes = notes + chosen
    refitted = None
    if refit is not None:
        chosen_model, (model, refitted, more) = model, refit(model, kept, rows)
        notes = notes + more
        if refitted is not None and "test" in dataset.splits:  # reported only, as every test score
            before = free_run_nrmse(chosen_model, dataset.test, float64=True)
            refitted["chosen_test_nrmse"] = None if before is None else before.mean
    test = free_run_nrmse(model, dataset.test, float64=True) if "test" in dataset.splits else None
    window = free_run_nrmse(model, dataset.test, float64=True, context=n) if n > 1 and test is not None else None
    summary = {"best_valid_nrmse": valid_nrmse, "test_nrmse": None if test is None else test.mean,
               "test_nrmse_window": None if window is None else window.mean, "stop_reason": "seeds",
               "keep": keep, "seeds": rows, "valid_samples": valid.n_samples, "notes": notes + valid_notes,
               "refit": refitted}
    save_checkpoint(out, model, train_config=cfg.to_dict(), history=[], best_epoch=None, summary=summary)
    model = load_model(out)
    return SeedsResult(model, keep, valid_nrmse, test, window, rows, out, notes + valid_notes, refitted)
