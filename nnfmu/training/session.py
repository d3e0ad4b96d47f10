"""The epoch loop behind :func:`nnfmu.training.train`: batches, early stopping, checkpoints, stops.

One :class:`Session` holds the mutable training state (optimizer, best
weights, early-stopping counter, history), so that it can be written to a
checkpoint and restored by ``resume``. The file is written on an improvement
(at most every :data:`SAVE_EVERY_S` seconds), at least every :data:`REFRESH_S`
seconds, at the end, and on a signal or an error; each write holds the state at
the end of the last finished epoch.
"""

from __future__ import annotations

import contextlib
import copy
import math
import signal
import threading
import time
from pathlib import Path

import torch

from nnfmu.errors import ConfigError, TrainingError
from nnfmu.models.base import StepModel
from nnfmu.models.checkpoint import save_checkpoint, state_snapshot
from nnfmu.training.averaging import WeightAverage
from nnfmu.training.batches import epoch_batches, masked_mse
from nnfmu.training.compiled_rollout import training_rollout
from nnfmu.training.config import TrainConfig
from nnfmu.training.evaluate import score
from nnfmu.training.horizons import lr_factor, with_context
from nnfmu.training.lr_plateau import RateSchedule
from nnfmu.training.physics_schedule import PhysicsSchedule
from nnfmu.training.resources import adamw, cpu_state


@contextlib.contextmanager
def flush_denormals():
    """Flush denormal floats to zero while training.

    Backpropagation through a long free run shrinks the adjoints geometrically
    (vanishing gradients) into the denormal range, where x86 arithmetic is about
    100 times slower: measured on GRU-32 rollouts of 500 steps, the first epochs ran
    at 0.7k instead of 160k trajectory-steps/s. Values below 1e-38 (float32) do not
    matter for training. torch has no getter, so the default (off) is restored afterwards.
    """
    torch.set_flush_denormal(True)
    try:
        yield
    finally:
        torch.set_flush_denormal(False)


#: Seconds between checkpoint writes: an improvement waits at most this long, and any epoch at most REFRESH_S.
SAVE_EVERY_S = 2.0
REFRESH_S = 30.0


class StopTraining(Exception):
    """Raise this from a training callback to stop training gracefully (the best weights are kept)."""


class StopRequests:
    """Context manager turning SIGINT/SIGTERM into a flag the loop polls; a second signal aborts at once.

    Signal handlers can only be installed in the main thread; elsewhere (e.g. a
    hyperparameter-search worker) the flag simply never rises.
    """

    def __init__(self) -> None:
        self.reason: str | None = None
        self._previous: dict = {}

    def _handle(self, signum, frame) -> None:
        if self.reason is not None:
            raise KeyboardInterrupt
        self.reason = signal.Signals(signum).name

    def __enter__(self) -> "StopRequests":
        if threading.current_thread() is threading.main_thread():
            for sig in (signal.SIGINT, signal.SIGTERM):
                self._previous[sig] = signal.signal(sig, self._handle)
        return self

    def __exit__(self, *exc) -> None:
        for sig, handler in self._previous.items():
            signal.signal(sig, handler)


class Session:
    """Mutable state of one training run; see :func:`nnfmu.training.train`."""

    def __init__(self, model: StepModel, cfg: TrainConfig, train_seqs: list, valid, out: Path | None):
        self.model, self.cfg, self.train_seqs, self.valid, self.out = model, cfg, train_seqs, valid, out
        self.schedule = PhysicsSchedule(model, cfg.physics_schedule)
        self.optimizer = adamw(self.schedule.groups(model), lr=cfg.lr, weight_decay=cfg.weight_decay)
        if cfg.feedback_noise and not model.takes_feedback_noise:
            raise ConfigError(f"a {type(model).__name__} feeds back no output that feedback_noise could disturb; "
                              "train it with feedback_noise=0")
        self.average = WeightAverage(model, cfg)
        self.rate = RateSchedule(cfg)
        self.context = model.config.init_window - 1  # samples before each training free run, for the init window
        self.epoch = 0
        self.history: list[dict] = []
        self.best_state = state_snapshot(model)
        self.best_epoch = 0
        self.best_score = math.inf
        self.bad_epochs = 0
        self.elapsed_before = 0.0
        self.started = time.monotonic()
        self.snapshot: dict | None = None  # the resume state at the end of the last finished epoch
        self.last_write = -math.inf
        self.unsaved_improvement = False

    # ---- one epoch ---------------------------------------------------------------------------
    def train_epoch(self, stop: StopRequests, deadline: float | None) -> tuple[float, bool]:
        """One pass over the training data; returns (mean loss, whether it ended early)."""
        cfg, model = self.cfg, self.model
        generator = torch.Generator().manual_seed(cfg.seed * 1_000_003 + self.epoch + 1)
        total, count, early = 0.0, 0, False
        model.train()
        truncate = None if cfg.truncate is None else cfg.truncate + self.context
        batches = list(epoch_batches(self.train_seqs, batch_size=cfg.batch_size, truncate=truncate,
                                     generator=generator))
        model.feedback_noise = cfg.feedback_noise if cfg.strategy == "parallel" else 0.0
        try:
            free_run = training_rollout(model)  # after train() and feedback_noise: they decide the compiled path
            for b, batch in enumerate(batches):
                un, yn, mask, past = with_context(batch, self.context)
                if cfg.strategy == "parallel":
                    pred = free_run(un, yn, past)
                else:
                    feed = yn + cfg.feedback_noise * torch.randn_like(yn) if cfg.feedback_noise else yn
                    pred = model.rollout_normalised(un, yn[:, 0], feed, past)
                loss = masked_mse(pred, yn, mask)
                self.optimizer.zero_grad(set_to_none=True)
                loss.backward()
                norm = torch.nn.utils.clip_grad_norm_(model.parameters(), cfg.clip if cfg.clip > 0 else math.inf)
                if not (torch.isfinite(loss) and torch.isfinite(norm)):
                    self._diverged(float(loss.detach()), b)
                factor = lr_factor(cfg, (self.epoch + b / len(batches)) / cfg.epochs) * self.rate.level
                for group in self.optimizer.param_groups:  # lr_scale: nnfmu.training.physics_schedule
                    group["lr"] = cfg.lr * group.get("lr_scale", 1.0) * factor
                self.optimizer.step()
                self.average.after_step()
                total += float(loss.detach()) * len(un)
                count += len(un)
                if stop.reason or (deadline is not None and time.monotonic() > deadline):
                    early = True
                    break
        finally:
            model.feedback_noise = 0.0
        if not stop.reason:
            self.average.after_epoch(self.epoch + 1)
        return total / max(count, 1), early

    def _diverged(self, loss: float, batch: int) -> None:
        kept = f"; the best weights so far are kept in {self.out}" if self.out else ""
        raise TrainingError(
            f"the training loss became {loss} (or its gradient non-finite) in epoch {self.epoch + 1}, "
            f"batch {batch + 1}; "
            f"lower the learning rate (lr={self.cfg.lr:g}), keep gradient clipping on (clip={self.cfg.clip:g}), "
            f"use truncation for long trajectories, or check the data for outliers{kept}"
        )

    # ---- bookkeeping -------------------------------------------------------------------------
    def validate(self) -> float:
        """Free-run NRMSE on the validation runs (after the init window), with the averaged weights if any."""
        with self.average.applied():
            return score(self.model, self.valid, context=self.context + 1)

    def record(self, train_loss: float | None, valid_nrmse: float, seconds: float, partial: bool) -> dict:
        """Append the epoch's metrics, update the kept weights (the best, or the last: ``keep_weights``) and the
        early-stopping counter."""
        improved = valid_nrmse < self.best_score
        if improved or self.cfg.keep_weights == "last":
            self.best_score, self.best_epoch = valid_nrmse, self.epoch
            with self.average.applied():
                self.best_state = state_snapshot(self.model)
            self.bad_epochs = 0
        elif self.epoch > 0:
            self.bad_epochs += 1
        decayed = self.epoch > 0 and not self.patience_exhausted() and self.rate.after_epoch(improved)
        if decayed:
            self.model.load_state_dict(self.best_state)  # the smaller rate goes on from the best weights
        entry = {"epoch": self.epoch, "train_loss": train_loss, "valid_nrmse": valid_nrmse,
                 "best_valid_nrmse": self.best_score, "best_epoch": self.best_epoch, "improved": improved,
                 "seconds": seconds, "partial": partial}
        if self.rate.mode:
            entry.update(lr_factor=self.rate.level, lr_decayed=decayed)  # the factor for the next epoch
        self.history.append(entry)
        self.snapshot = self.resume_state()  # what a write after a signal or an error holds
        for part in ("optimizer", "average"):  # the weights are copies already; these still reference live tensors
            self.snapshot[part] = copy.deepcopy(self.snapshot[part])
        self.unsaved_improvement |= improved
        return entry

    def save_due(self) -> bool:
        """Whether the checkpoint should be written now: an improvement not written for :data:`SAVE_EVERY_S`,
        or nothing written for :data:`REFRESH_S` (short epochs otherwise spent a third of a budget writing)."""
        wait = SAVE_EVERY_S if self.unsaved_improvement else REFRESH_S
        return time.monotonic() - self.last_write >= wait

    def patience_exhausted(self) -> bool:
        return self.cfg.patience > 0 and self.bad_epochs >= self.rate.patience_now()

    def next_stage(self) -> bool:
        """The patience out: True where ``lr_schedule='anneal'`` goes on at a lower rate from the best weights."""
        if not self.rate.next_stage():
            return False
        self.model.load_state_dict(self.best_state)
        self.bad_epochs = 0
        return True

    @property
    def elapsed(self) -> float:
        return self.elapsed_before + time.monotonic() - self.started

    def resume_state(self) -> dict:
        return {"epoch": self.epoch, "state_dict": state_snapshot(self.model),
                "optimizer": cpu_state(self.optimizer.state_dict()), "torch_rng": torch.get_rng_state(),
                "bad_epochs": self.bad_epochs, "best_valid_nrmse": self.best_score, "elapsed_s": self.elapsed,
                "average": cpu_state(self.average.state_dict()), **self.schedule.state(), **self.rate.state()}

    def restore(self, ckpt: dict) -> None:
        """Continue from a checkpoint written by :meth:`save` (its ``resume`` section)."""
        r = ckpt["resume"]
        self.model.load_state_dict(r["state_dict"])
        self.optimizer.load_state_dict(r["optimizer"])
        torch.set_rng_state(r["torch_rng"])
        self.epoch, self.bad_epochs = int(r["epoch"]), int(r["bad_epochs"])
        self.elapsed_before = float(r["elapsed_s"])
        self.best_score = float(r["best_valid_nrmse"])
        self.best_state = {k: v.clone() for k, v in ckpt["state_dict"].items()}
        self.best_epoch = int(ckpt["best_epoch"])
        self.history = list(ckpt["history"])
        if "average" in r:
            self.average.load_state_dict(r["average"])
        self.schedule.restore(r)
        self.rate.restore(r)

    def save(self, summary: dict | None = None) -> None:
        """Write the checkpoint: the best weights, the history and the last finished epoch's resume state."""
        if self.out is None:
            return
        save_checkpoint(self.out, self.model, state_dict=self.best_state, train_config=self.cfg.to_dict(),
                        history=self.history, best_epoch=self.best_epoch,
                        summary={"best_valid_nrmse": self.best_score, "epochs_run": self.epoch, **(summary or {})},
                        resume=self.snapshot if self.snapshot is not None else self.resume_state())
        self.last_write, self.unsaved_improvement = time.monotonic(), False
