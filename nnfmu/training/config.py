"""``TrainConfig``: every option of the one trainer, typed, frozen and keyword-only.

The defaults suit the valve data (normalised outputs, Ts = 40 µs, 500-step
training trajectories); the paper tunes them per architecture and strategy.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Mapping

from nnfmu.errors import ConfigError, check_options

STRATEGIES = ("parallel", "series-parallel")
DTYPES = ("float32", "float64")
AVERAGES = ("none", "ema", "swa")
LR_SCHEDULES = ("constant", "cosine", "plateau", "anneal")
VALID_HORIZONS = ("auto", "split", "joined")
PHYSICS_SCHEDULES = ("joint", "staged")  # nnfmu.training.physics_schedule
KEEP_WEIGHTS = ("best", "last")  # "last": a refit (nnfmu.training.refit)


@dataclass(frozen=True, kw_only=True)
class TrainConfig:
    """Options of :func:`nnfmu.training.train`.

    Attributes
    ----------
    strategy : {'parallel', 'series-parallel'}
        Parallel: the loss is on the free run (the model feeds back its own
        predictions, gradients flow through the whole rollout). Series-parallel:
        the loss is one step ahead with the measured outputs fed in.
    epochs : int
        Maximum number of passes over the training split; :data:`nnfmu.limits.UNBOUNDED_EPOCHS` with
        ``max_minutes`` lets the wall-clock budget alone end the training.
    batch_size : int
        Trajectories (or truncated windows) per optimiser step.
    lr, weight_decay : float
        AdamW learning rate and decoupled weight decay.
    clip : float
        Maximum gradient 2-norm; 0 disables clipping.
    patience : int
        Stop after this many epochs without a better validation free-run NRMSE; 0 disables early stopping.
    truncate : int or None
        Cut the training trajectories into windows of this many samples
        (multiple shooting), each started from its measured first output;
        the cut positions shift randomly from epoch to epoch. None: whole trajectories.
    seed : int
        Seeds the weight initialisation, the batch order and dropout.
    max_minutes : float or None
        Wall-clock budget of one call; the epoch running when it ends is validated and kept.
    valid_fraction : float
        Share of the training split carved out for validation when the dataset has no 'valid' split.
    valid_blocks : int
        One training record without a 'valid' split: the validation is ``valid_blocks`` blocks spread over the
        record (blocked cross-validation's hold-out), each ``valid_fraction / valid_blocks`` long; 1: its tail.
    dtype : {'float32', 'float64'}
        Precision of training (evaluation of the test split is always float64).
    feedback_noise : float
        Std of white noise added to the output fed back in the training free runs (parallel) or
        to the measured outputs fed in (series-parallel), in units of each output's training
        std. The network learns to pull a disturbed output back instead of drifting with it.
    average : {'none', 'ema', 'swa'}
        Weight averaging: 'ema' keeps an exponential moving average of the weights (decay
        ``average_decay`` per optimiser step); 'swa' the plain mean of the weights at the end of
        every epoch from epoch ``average_start * epochs`` on. Validation, early stopping and
        the checkpoint's best weights use the averaged weights.
    average_decay : float
        EMA decay per optimiser step, in (0, 1).
    average_start : float
        SWA: the fraction of ``epochs`` after which the epoch-end weights are averaged.
    lr_schedule : {'constant', 'cosine', 'plateau', 'anneal'}
        'cosine': the learning rate falls from ``lr`` to ``lr * lr_final`` over ``epochs``
        (per optimiser step, half a cosine period), so the preset's epochs fix the whole run.
        'plateau': it falls by a factor of 0.3, down to ``lr * lr_final``, after a quarter of ``patience``
        epochs without a better validation free run, and training goes on from the best weights. 'anneal': constant
        until the patience runs out, then from the best weights at 0.1 times the rate with a quarter of the patience,
        again, down to ``lr * lr_final`` (:mod:`nnfmu.training.lr_plateau`). Both count against ``patience``: with 0
        (no early stopping, as ``max_minutes`` alone sets it for a hybrid) the rate stays constant, and the run says so.
    lr_final : float
        Final learning rate of the cosine schedule, and the lowest of 'plateau' and 'anneal', as a fraction of ``lr``.
    join : bool
        Join the training trajectories end to end, in order, into one record before cutting
        ``truncate``-sample windows: for data cut from one continuous recording (the robot
        benchmark's pieces), so that training windows may be as long as the free runs to survive.
    valid_horizon : {'auto', 'split', 'joined'}
        What the validation free run covers: 'split' every validation trajectory on its own;
        'joined' the validation trajectories end to end as one record (as the robot's test
        record is scored); 'auto' joins them when the dataset says its pieces are consecutive
        (``source["contiguous"]``) and the test trajectories are longer than the validation ones.
    physics_schedule : {'joint', 'staged'}
        When a hybrid's trained physical parameters (``train_physics``) learn: 'joint' with the network from the
        start; 'staged' frozen first, then joint at a tenth of ``lr`` (:mod:`nnfmu.training.physics_schedule`).
        Networks have none; it does not apply to them.
    keep_weights : {'best', 'last'}
        Which weights the run keeps: 'best' those of the epoch best on validation (early stopping's); 'last' those
        of the last epoch, for a refit on the training and validation data together, where the validation score is
        in-sample and chooses nothing (:mod:`nnfmu.training.refit`).
    """

    strategy: str = "parallel"
    epochs: int = 100
    batch_size: int = 64
    lr: float = 3e-3
    weight_decay: float = 1e-4
    clip: float = 1.0
    patience: int = 15
    truncate: int | None = None
    seed: int = 0
    max_minutes: float | None = None
    valid_fraction: float = 0.1
    valid_blocks: int = 1
    dtype: str = "float32"
    feedback_noise: float = 0.0
    average: str = "none"
    average_decay: float = 0.999
    average_start: float = 0.5
    lr_schedule: str = "constant"
    lr_final: float = 0.01
    join: bool = False
    valid_horizon: str = "auto"
    physics_schedule: str = "joint"
    keep_weights: str = "best"

    def __post_init__(self) -> None:
        for name, valid in (("strategy", STRATEGIES), ("dtype", DTYPES), ("average", AVERAGES),
                            ("lr_schedule", LR_SCHEDULES), ("valid_horizon", VALID_HORIZONS),
                            ("physics_schedule", PHYSICS_SCHEDULES),
                            ("keep_weights", KEEP_WEIGHTS)):
            if getattr(self, name) not in valid:
                raise ConfigError(f"unknown {name} {getattr(self, name)!r}; choose one of {', '.join(valid)}")
        for name in ("average_decay", "average_start", "lr_final"):
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and 0.0 < value < 1.0):
                raise ConfigError(f"{name} must be a number in (0, 1), got {value!r}")
        if not (isinstance(self.feedback_noise, (int, float)) and 0.0 <= self.feedback_noise < math.inf):
            raise ConfigError(f"feedback_noise must be a finite number >= 0 (a fraction of the output std), "
                              f"got {self.feedback_noise!r}")
        object.__setattr__(self, "join", bool(self.join))
        for name, low in (("epochs", 1), ("batch_size", 1), ("patience", 0), ("valid_blocks", 1)):
            value = getattr(self, name)
            if not isinstance(value, int) or isinstance(value, bool) or value < low:
                raise ConfigError(f"{name} must be an integer >= {low}, got {value!r}")
        if self.truncate is not None and (not isinstance(self.truncate, int) or self.truncate < 2):
            raise ConfigError(f"truncate must be None or an integer >= 2 samples, got {self.truncate!r}")
        for name in ("lr", "weight_decay", "clip"):
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value >= 0):
                raise ConfigError(f"{name} must be a finite number >= 0, got {value!r}")
        if not self.lr > 0:
            raise ConfigError(f"lr must be > 0, got {self.lr!r}")
        if self.max_minutes is not None and not (isinstance(self.max_minutes, (int, float)) and self.max_minutes > 0):
            raise ConfigError(f"max_minutes must be None or > 0, got {self.max_minutes!r}")
        if not 0.0 < self.valid_fraction < 1.0:
            raise ConfigError(f"valid_fraction must be in (0, 1), got {self.valid_fraction!r}")

    def to_dict(self) -> dict:
        return dataclasses.asdict(self)

    @classmethod
    def from_dict(cls, d: Mapping) -> "TrainConfig":
        """Rebuild from :meth:`to_dict`; unknown keys raise :class:`~nnfmu.errors.UnknownOptionError`."""
        check_options(d, {f.name for f in dataclasses.fields(cls)}, "TrainConfig")
        return cls(**dict(d))

    def replace(self, **changes) -> "TrainConfig":
        check_options(changes, {f.name for f in dataclasses.fields(self)}, "TrainConfig")
        return dataclasses.replace(self, **changes)
