"""``Hyper``: the searched or preset hyperparameters of one architecture (a network and its training)."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Mapping

from nnfmu.errors import check_options
from nnfmu.models import ARCHS, ModelConfig
from nnfmu.training import TrainConfig

_MODEL_FIELDS = ("hidden", "layers", "window", "kernel_size", "dropout", "increment", "init_window")
_TRAIN_FIELDS = ("lr", "weight_decay", "clip", "batch_size", "truncate", "feedback_noise", "average",
                 "average_decay", "lr_schedule", "join")


@dataclass(frozen=True, kw_only=True)
class Hyper:
    """Hyperparameters of one architecture: the searched or preset part of a network and its training.

    Attributes
    ----------
    hidden, layers, window, kernel_size, dropout, increment, init_window :
        As in :class:`nnfmu.models.ModelConfig` (``layers``/``window`` None: the architecture's default).
    lr, weight_decay, clip, batch_size, truncate, feedback_noise, average, average_decay, lr_schedule, join :
        As in :class:`nnfmu.training.TrainConfig`.
    """

    hidden: int = 32
    layers: int | None = None
    window: int | None = None
    kernel_size: int = 3
    dropout: float = 0.0
    increment: bool = False
    init_window: int = 1
    lr: float = 3e-3
    weight_decay: float = 1e-4
    clip: float = 1.0
    batch_size: int = 64
    truncate: int | None = None
    feedback_noise: float = 0.0
    average: str = "none"
    average_decay: float = 0.999
    lr_schedule: str = "constant"
    join: bool = False

    def model_config(self, arch: str, n_u: int, n_y: int) -> ModelConfig:
        """The :class:`ModelConfig` of ``arch`` for a system with ``n_u`` inputs and ``n_y`` outputs."""
        return ModelConfig(arch=arch, n_u=n_u, n_y=n_y, **{k: getattr(self, k) for k in _MODEL_FIELDS})

    def train_config(self, *, strategy: str, epochs: int, patience: int, seed: int,
                     max_minutes: float | None) -> TrainConfig:
        """The :class:`TrainConfig` for one training of ``epochs`` epochs at most."""
        return TrainConfig(strategy=strategy, epochs=epochs, patience=patience, seed=seed,
                           max_minutes=max_minutes, **{k: getattr(self, k) for k in _TRAIN_FIELDS})

    def replace(self, **changes) -> "Hyper":
        check_options(changes, {f.name for f in dataclasses.fields(self)}, "Hyper")
        return dataclasses.replace(self, **changes)

    def to_dict(self) -> dict:
        return dataclasses.asdict(self)

    @classmethod
    def from_dict(cls, d: Mapping) -> "Hyper":
        check_options(d, {f.name for f in dataclasses.fields(cls)}, "Hyper")
        return cls(**dict(d))


def per_arch(**hyper: Hyper) -> dict[str, Hyper]:
    """``{arch: Hyper}`` in the order of :data:`nnfmu.models.ARCHS`."""
    return {a: hyper[a] for a in ARCHS if a in hyper}
