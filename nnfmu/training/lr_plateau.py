"""The learning-rate schedules that follow validation: ``lr_schedule='plateau'`` and ``'anneal'``.

A free run's validation NRMSE is noisy from epoch to epoch at a constant learning rate, and the weights kept are a
low point of a noisy curve (docs/accuracy.md). Both schedules go back to the best weights so far whenever they lower
the rate (the optimiser keeps its moment estimates), down to ``lr * lr_final``:

- ``plateau``: after :func:`plateau_wait` epochs without a better validation free run (a quarter of the
  early-stopping patience) the rate is multiplied by :data:`PLATEAU_FACTOR`. The early-stopping counter is not
  reset, so a run without improvements stops after ``patience`` epochs, as at a constant rate.
- ``anneal``: the constant rate until the patience runs out, then the rate times :data:`ANNEAL_FACTOR` with a
  quarter of the patience, again until ``lr_final``. The constant stage is the constant schedule's run itself,
  so the kept weights are never worse on validation than the constant schedule's; it costs the later stages' epochs.

Both count epochs against the early-stopping patience; with ``patience`` 0 the rate stays constant.
"""

from __future__ import annotations

from nnfmu.training.config import TrainConfig

#: ``plateau``: the rate's factor at each decay
PLATEAU_FACTOR = 0.3
#: ``anneal``: the rate's factor at each stage after the first
ANNEAL_FACTOR = 0.1
#: the share of the patience that ``plateau`` waits before a decay, and that an ``anneal`` stage after the first gets
PATIENCE_SHARE = 4


def plateau_wait(cfg: TrainConfig) -> int:
    """Epochs without a better validation score, since the last improvement or decay, before ``plateau`` decays."""
    return max(1, cfg.patience // PATIENCE_SHARE)


class RateSchedule:
    """One run's state: ``level`` (the factor on ``lr``), epochs since the last improvement or decay, decays."""

    def __init__(self, cfg: TrainConfig):
        # without a patience (0: no early stopping) there is nothing to count: the rate stays constant
        self.mode = cfg.lr_schedule if cfg.lr_schedule in ("plateau", "anneal") and cfg.patience > 0 else None
        self.patience, self.floor, self.wait = cfg.patience, cfg.lr_final, plateau_wait(cfg)
        self.level, self.stalled, self.decays = 1.0, 0, 0

    def patience_now(self) -> int:
        """The early-stopping patience of the current stage (``anneal``'s later stages get a quarter)."""
        return self.wait if self.mode == "anneal" and self.decays else self.patience

    def after_epoch(self, improved: bool) -> bool:
        """``plateau``: count an epoch; True where the rate falls now (the caller restores the best weights)."""
        if self.mode != "plateau":
            return False
        self.stalled = 0 if improved else self.stalled + 1
        if self.stalled < self.wait or self.at_floor():
            return False
        self._lower(PLATEAU_FACTOR)
        return True

    def next_stage(self) -> bool:
        """``anneal``, its patience out: True where a stage at a lower rate follows (the caller restores the best
        weights and restarts the patience); False where the run ends."""
        if self.mode != "anneal" or self.at_floor():
            return False
        self._lower(ANNEAL_FACTOR)
        return True

    def at_floor(self) -> bool:
        return self.level <= self.floor * (1.0 + 1e-9)  # 0.1 * 0.1 is 0.010000000000000002 in floating point

    def _lower(self, factor: float) -> None:
        self.level, self.stalled, self.decays = max(self.level * factor, self.floor), 0, self.decays + 1

    def state(self) -> dict:
        return {"lr_level": self.level, "lr_stalled": self.stalled, "lr_decays": self.decays}

    def restore(self, resume: dict) -> None:
        self.level = float(resume.get("lr_level", 1.0))
        self.stalled, self.decays = int(resume.get("lr_stalled", 0)), int(resume.get("lr_decays", 0))
