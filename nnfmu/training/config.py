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
        Maximum number of passes over the training split.
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
    dtype : {'float32', 'float64'}
        Precision of training (evaluation of the test split is always float64).
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
    dtype: str = "float32"

    def __post_init__(self) -> None:
        if self.strategy not in STRATEGIES:
            raise ConfigError(f"unknown strategy {self.strategy!r}; choose one of {', '.join(STRATEGIES)}")
        if self.dtype not in DTYPES:
            raise ConfigError(f"unknown dtype {self.dtype!r}; choose one of {', '.join(DTYPES)}")
        for name, low in (("epochs", 1), ("batch_size", 1), ("patience", 0)):
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
