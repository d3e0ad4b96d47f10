"""The one trainer for both strategies: :func:`train`.

A 20-line picture of what it does::

    model = build_model(model_config, dataset meta, normalisation of the train split)
    for epoch in 1..epochs:
        for batch of (normalised) trajectories or truncated windows:
            pred = model.rollout_normalised(un, yn[:, 0])          # parallel: free run
            pred = model.rollout_normalised(un, yn[:, 0], yn)      # series-parallel: teacher forcing
            loss = MSE(pred[:, 1:], yn[:, 1:]); AdamW step with gradient clipping
        valid = free-run NRMSE on the validation split           # both strategies
        keep the best weights; write the checkpoint; stop after `patience` epochs without progress
    test = free-run NRMSE (float64) of the best weights on the test split
"""

from __future__ import annotations

import copy
import json
import math
import os
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Mapping

import numpy as np
import torch

from nnfmu.data import Dataset, Trajectories
from nnfmu.errors import CheckpointError, ConfigError
from nnfmu.metrics import NrmseResult
from nnfmu.models import architectures
from nnfmu.models.base import StepModel, torch_threads
from nnfmu.models.checkpoint import load_checkpoint, model_from_checkpoint
from nnfmu.models.config import ModelConfig
from nnfmu.models.registry import build_model
from nnfmu.progress import advance, training_bar
from nnfmu.training.batches import normalised_sequences
from nnfmu.training.config import TrainConfig
from nnfmu.training.evaluate import free_run, free_run_nrmse
from nnfmu.training.horizons import join_sequences, validation_trajectories
from nnfmu.training.increments import prepare_increment
from nnfmu.training.linear_start import start_linear_path
from nnfmu.training.physics_schedule import STAGED_LR
from nnfmu.training.resources import check_threads, resolve_device
from nnfmu.training.session import Session, StopRequests, StopTraining, flush_denormals
from nnfmu.valid_range import training_range

Callback = Callable[[int, dict], None]
#: Preparing a model (building it, compiling its C) for this many seconds or more is reported through ``say``.
SAY_PREPARED_S = 1.0


@dataclass(frozen=True)
class TrainResult:
    """What :func:`train` returns.

    Attributes
    ----------
    model : StepModel
        The network with the best weights (lowest validation free-run NRMSE), in eval mode.
    history : list of dict
        Per epoch: ``epoch``, ``train_loss``, ``valid_nrmse``, ``best_valid_nrmse``, ``best_epoch``,
        ``improved``, ``seconds``, ``partial``. Epoch 0 is the untrained network.
    best_epoch : int
    best_valid_nrmse : float
    test : NrmseResult or None
        Free-run float64 scores of the best weights on the test split (None if
        the run was interrupted, the dataset has no test split, or the simulation diverged).
    stop_reason : str
        'epochs', 'early-stopping', 'time-budget', 'callback', 'SIGINT' or 'SIGTERM'.
    checkpoint : Path or None
    notes : list of str
        Things the user should know (e.g. a validation split was carved out of train).
    test_window : NrmseResult or None
        With an init window of N > 1 samples: the test score after the window (the model sees
        samples 0 .. N-1 and is scored on the rest); ``test`` is the free run from y0 alone.
    """

    model: StepModel
    history: list
    best_epoch: int
    best_valid_nrmse: float
    test: NrmseResult | None
    stop_reason: str
    checkpoint: Path | None
    elapsed_s: float
    notes: list = field(default_factory=list)
    test_window: NrmseResult | None = None

    @property
    def test_nrmse(self) -> float | None:
        return None if self.test is None else self.test.mean


def dataset_meta(ds: Dataset, arch: str) -> dict:
    """The model's ``meta``: name, Ts, channels, (JSON-clean) provenance and the training input range."""
    source = json.loads(json.dumps(dict(ds.source), default=_jsonable))
    system = source.get("system") or source.get("name") or source.get("kind") or "model"
    return {"name": f"{system}_{arch}", "Ts": float(ds.Ts), "inputs": [c.to_json() for c in ds.inputs],
            "outputs": [c.to_json() for c in ds.outputs], "source": source,
            "input_range": training_range(ds.train.u)}  # the FMU's valid input range (nnfmu.valid_range)


def _jsonable(v):
    if isinstance(v, np.generic):
        return v.item()
    if isinstance(v, np.ndarray):
        return v.tolist()
    return str(v)


def prepare_dataset(dataset: Dataset, cfg: TrainConfig) -> tuple[Dataset, list]:
    """``dataset`` with a validation split (carved by ``cfg.valid_fraction`` and ``cfg.seed`` if it has none), notes."""
    if not isinstance(dataset, Dataset):
        raise ConfigError(f"expected an nnfmu.data.Dataset, got {type(dataset).__name__}; "
                          "load one with nnfmu.load_dataset(folder)")
    if dataset.valid is not None:
        return dataset, []
    carved = dataset.with_validation(cfg.valid_fraction, seed=cfg.seed, blocks=cfg.valid_blocks)
    how = (f"{carved.valid.n_traj} of {dataset.train.n_traj} training trajectories" if dataset.train.n_traj >= 2
           else f"the last {cfg.valid_fraction:.0%} of the training record" if cfg.valid_blocks == 1
           else f"{cfg.valid_blocks} blocks spread over the training record, {cfg.valid_fraction:.0%} of it")
    return carved, [f"the dataset has no 'valid' split; validating on {how} (valid_fraction={cfg.valid_fraction})"]


def _new_model(model_config, dataset: Dataset, cfg: TrainConfig, linear=None) -> StepModel:
    if isinstance(model_config, StepModel):  # trained further as it is: its normalisation and meta are kept
        config = model_config.config
    else:
        config = ModelConfig.from_dict(model_config) if isinstance(model_config, Mapping) else model_config
    if not isinstance(config, ModelConfig):
        raise ConfigError(f"expected a ModelConfig, a dict or a StepModel, got {type(model_config).__name__}")
    if (config.n_u, config.n_y) != (dataset.n_u, dataset.n_y):
        raise ConfigError(f"the model config has n_u={config.n_u}, n_y={config.n_y} but the dataset has "
                          f"{dataset.n_u} inputs and {dataset.n_y} outputs; build the config from the dataset")
    if isinstance(model_config, StepModel):
        return model_config
    torch.manual_seed(cfg.seed)
    model = build_model(config, dataset_meta(dataset, config.arch), norm=dataset.norm_stats("train"))
    prepare_increment(model, dataset.train)
    if config.linear_order:
        start_linear_path(model, dataset, linear)
    return model


def _resumed_model(ckpt: dict, model_config, out: Path, dataset: Dataset) -> StepModel:
    if ckpt.get("resume") is None:
        raise CheckpointError(f"{out} holds no training state to resume from; train without resume")
    names = [[c["name"] for c in ckpt["meta"][k]] for k in ("inputs", "outputs")]
    if names != [dataset.input_names, dataset.output_names] or ckpt["meta"]["Ts"] != dataset.Ts:
        raise ConfigError(f"cannot resume {out}: it was trained on inputs {names[0]}, outputs {names[1]}, "
                          f"Ts {ckpt['meta']['Ts']:g} s, but the dataset has {dataset.input_names}, "
                          f"{dataset.output_names}, Ts {dataset.Ts:g} s; resume on the same dataset")
    stored = ModelConfig.from_dict(ckpt["model_config"])
    given = model_config.config if isinstance(model_config, StepModel) else model_config
    if isinstance(given, Mapping):
        given = ModelConfig.from_dict(given)
    if given is not None and given != stored:
        raise ConfigError(f"cannot resume {out}: it was trained with {stored}, now asked for {given}; "
                          "resume with the same model options, or train into a new --out file")
    return model_from_checkpoint(ckpt, state_dict=ckpt["resume"]["state_dict"], where=str(out))


def train(
    dataset: Dataset,
    model_config: ModelConfig | Mapping | StepModel | None,
    train_config: TrainConfig | Mapping | None = None,
    *,
    out: str | os.PathLike | None = None,
    resume: bool = False,
    progress: bool = False,
    callback: Callback | None = None,
    device: str | torch.device | None = "auto",
    threads: int | None = None,
    linear=None,
    say: Callable[[str], None] | None = None,
) -> TrainResult:
    """Train a step network in parallel or series-parallel mode; early stopping on validation free-run NRMSE.

    Parameters
    ----------
    dataset : Dataset
        Physical-unit data; normalisation statistics come from its train split.
        Without a ``valid`` split, ``train_config.valid_fraction`` of it is carved out (see ``notes``).
    model_config : ModelConfig, dict or StepModel
        The network to build (seeded with ``train_config.seed``), or a model to go on
        training. With ``resume`` it may be None (the checkpoint's config is used).
    train_config : TrainConfig or dict, optional
        Defaults to ``TrainConfig()``; with ``resume`` and None, the checkpoint's.
    out : path, optional
        Checkpoint file, rewritten atomically (best weights + resume state) on an improvement, at least every
        30 s, at the end and on a signal or an error (:mod:`nnfmu.training.session`).
    resume : bool
        Continue the run stored in ``out``; with the same seed the result equals an uninterrupted run.
    progress : bool
        Show a tqdm bar with the loss and the validation NRMSE.
    callback : callable, optional
        ``callback(epoch, metrics)`` after every epoch; raise :class:`StopTraining` to stop.
    device : {'auto', 'cpu', 'cuda'} or 'cuda:N'
        Where to train (:func:`nnfmu.training.resources.resolve_device`); the returned model
        is on the CPU and the checkpoint holds CPU tensors whatever the device.
    threads : int, optional
        Intra-op torch threads of this training (default one: the measured policy of
        :mod:`nnfmu.training.resources`); the caller's setting is restored afterwards.
    linear : nnfmu.linear.LinearModel, optional
        With ``model_config.linear_order = n_z > 0``: the linear model of ``n_z`` states the network starts
        from (:mod:`nnfmu.models.linear_path`); None identifies one of that order on the training split.
    say : callable, optional
        ``say(line)`` for what the user should know before the epochs start: how long preparing the model took
        (its C compiled, or taken from the cache), when that took :data:`SAY_PREPARED_S` or more. The
        ``max_minutes`` budget starts after it.

    Raises
    ------
    TrainingError
        If the loss becomes NaN or infinite.
    DataError, ConfigError, CheckpointError
        For bad data, options or checkpoints.
    """
    out = None if out is None else Path(out)
    ckpt = None
    if resume:
        if out is None:
            raise ConfigError("resume=True needs out=<checkpoint path> to resume from")
        ckpt = load_checkpoint(out)
        if train_config is None and ckpt.get("train_config"):
            train_config = TrainConfig.from_dict(ckpt["train_config"])
    cfg = _as_train_config(train_config)
    dataset, notes = prepare_dataset(dataset, cfg)
    valid, valid_notes = validation_trajectories(dataset, cfg)
    notes += valid_notes
    if cfg.lr_schedule in ("plateau", "anneal") and cfg.patience == 0:
        notes.append(f"lr_schedule {cfg.lr_schedule!r} counts epochs against the patience, which is 0 (no early "
                     "stopping): the learning rate stays constant; give a patience (--patience N) for it to fall")
    dtype, device = getattr(torch, cfg.dtype), resolve_device(device)
    with torch.random.fork_rng(devices=[]), flush_denormals(), torch_threads(check_threads(threads)):
        started = time.monotonic()
        if ckpt:
            model = _resumed_model(ckpt, model_config, out, dataset)
        else:
            model = _new_model(model_config, dataset, cfg, linear)
        model = model.to(dtype)
        _check_device(model, device)
        seqs = [(un.to(device), yn.to(device)) for un, yn in normalised_sequences(model, dataset.train, dtype, "train")]
        model = model.to(device)
        session = Session(model, cfg, join_sequences(seqs) if cfg.join else seqs, valid, out)
        if ckpt:
            session.restore(ckpt)
        _prepared(session, time.monotonic() - started, say)
        try:
            stop_reason = _run(session, progress, callback)
        except BaseException:
            _save_quietly(session)  # a diverged loss or a second Ctrl-C: the last finished epoch is kept
            raise
        test = test_window = None
        if stop_reason not in ("SIGINT", "SIGTERM"):  # an interrupted run stops at once; the file is up to date
            best = copy.deepcopy(model).eval()
            best.load_state_dict(session.best_state)
            test, test_window = _test_scores(best, dataset)
            # still inside fork_rng: the resume state saved here holds the training RNG, not the caller's
            session.save({"test_nrmse": None if test is None else test.mean, "stop_reason": stop_reason,
                          "test_nrmse_window": None if test_window is None else test_window.mean,
                          "valid_samples": valid.n_samples, "notes": notes})
    model = model.cpu()
    model.load_state_dict(session.best_state)
    model.eval()
    return TrainResult(model, session.history, session.best_epoch, session.best_score, test, stop_reason,
                       out, session.elapsed, notes, test_window)



def _test_scores(model: StepModel, dataset: Dataset) -> tuple[NrmseResult | None, NrmseResult | None]:
    """Float64 free-run test scores: from the measured y0, and (init window N > 1) after the first N samples."""
    if "test" not in dataset.splits:
        return None, None
    n = model.config.init_window
    window = free_run_nrmse(model, dataset.test, float64=True, context=n) if n > 1 else None
    return free_run_nrmse(model, dataset.test, float64=True), window


def _check_device(model: StepModel, device: torch.device) -> None:
    """Its architecture's own check (``Architecture.check_device``: the hybrid's compiled physics is CPU only)."""
    check = architectures.architecture(model.config.arch).get("check_device")
    if check is not None:
        check(model.config, device)


def _as_train_config(train_config) -> TrainConfig:
    if train_config is None:
        return TrainConfig()
    if isinstance(train_config, Mapping):
        return TrainConfig.from_dict(train_config)
    if not isinstance(train_config, TrainConfig):
        raise ConfigError(f"expected a TrainConfig or a dict, got {type(train_config).__name__}")
    return train_config


def _prepared(session: Session, seconds: float, say: Callable[[str], None] | None) -> None:
    """Run the model once on a few validation samples, so that whatever its free runs compile (a hybrid's whole
    step, :mod:`nnfmu.hybrid.fused`; a recurrent network's C rollout) is compiled before the budget starts, and
    say how long building and compiling took. No weight or random state changes (no gradient, eval mode)."""
    t0 = time.monotonic()
    valid, context = session.valid, session.context + 1
    n = min(int(valid.lengths[0]), context + 2)
    free_run(session.model, Trajectories((valid.u[0][:n],), (valid.y[0][:n],)), context=context)
    seconds += time.monotonic() - t0
    if say is not None and seconds >= SAY_PREPARED_S:
        say(f"prepared the model in {seconds:.1f} s (building it and compiling its C, which is cached for later "
            "runs); the training budget starts now")


def _run(session: Session, progress: bool, callback: Callback | None) -> str:
    """The epoch loop; returns why it stopped."""
    cfg = session.cfg
    deadline = None if cfg.max_minutes is None else time.monotonic() + 60.0 * cfg.max_minutes
    if session.epoch == 0 and not session.history:
        session.record(None, session.validate(), 0.0, False)
        session.save()
    bar = training_bar(session.epoch, cfg.epochs, cfg.max_minutes, progress=progress,
                       desc=f"{session.model.config.arch} {cfg.strategy}")
    with StopRequests() as stop, bar:
        _show(bar, session.history[-1])
        while session.epoch < cfg.epochs:
            if session.patience_exhausted():
                if not session.next_stage():
                    break
                bar.write(f"epoch {session.epoch}: learning rate {cfg.lr * session.rate.level:.3g} from here on, from "
                          f"the best weights (epoch {session.best_epoch}), for up to {session.rate.patience_now()} "
                          "epochs without a better validation score (anneal schedule)")
            t0 = time.monotonic()  # an epoch always starts: at least one batch per call, even over budget
            loss, early = session.train_epoch(stop, deadline)
            if stop.reason:
                session.save()  # the unfinished epoch is dropped; the file holds the last finished one
                return stop.reason
            session.epoch += 1
            entry = session.record(loss, session.validate(), time.monotonic() - t0, early)
            if session.save_due():
                session.save()
            _show(bar, entry)
            advance(bar, session.epoch)
            _next_stage(session, bar, deadline)
            if entry.get("lr_decayed"):
                bar.write(f"epoch {session.epoch}: learning rate {cfg.lr * session.rate.level:.3g} from here on, "
                          f"from the best weights (epoch {session.best_epoch}): no better validation score for "
                          f"{session.rate.wait} epochs (plateau schedule)")
            if callback is not None:
                try:
                    callback(session.epoch, dict(entry))
                except StopTraining:
                    session.save()
                    return "callback"
            if early:
                return "time-budget"
        return "early-stopping" if session.patience_exhausted() else "epochs"


def _next_stage(session: Session, bar, deadline: float | None) -> None:
    """``physics_schedule='staged'``: the physical parameters join the training when their frozen stage ends."""
    cfg = session.cfg
    budget = None if deadline is None else (deadline - 60.0 * cfg.max_minutes, deadline)
    if session.schedule.due(session.epoch, cfg.epochs, budget, session.patience_exhausted()):
        session.schedule.start_joint()
        session.bad_epochs = 0  # the joint stage gets its own patience
        bar.write(f"epoch {session.epoch}: the physical parameters train from here on (staged schedule), at "
                  f"{STAGED_LR:g} times the learning rate")


def _save_quietly(session: Session) -> None:
    """Write the checkpoint on the way out of an error; a failure to write must not hide the error itself."""
    try:
        session.save()
    except Exception:  # noqa: BLE001 - the original error is raised by the caller
        pass


def _show(bar, entry: dict) -> None:
    loss = entry["train_loss"]
    bar.set_postfix(loss="-" if loss is None else f"{loss:.3g}", valid=f"{entry['valid_nrmse']:.4f}",
                    best=f"{entry['best_valid_nrmse']:.4f}@{entry['best_epoch']}", refresh=True)
    if not math.isfinite(entry["valid_nrmse"]):
        bar.write(f"epoch {entry['epoch']}: the validation free run diverged (non-finite outputs)")
