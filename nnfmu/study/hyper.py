"""``Hyper``: the searched or preset hyperparameters of one architecture (a network and its training).

Its fields and defaults are those of :class:`~nnfmu.models.ModelConfig` and
:class:`~nnfmu.training.TrainConfig`, read from them, less the ones a single run sets rather than a
recipe (:data:`RUN_MODEL_FIELDS`, :data:`RUN_TRAIN_FIELDS`), so a field added to a config is a
hyperparameter without an edit here (once ``valid_horizon`` was lost in a copied list).
"""

from __future__ import annotations

import dataclasses
import typing
from typing import Mapping

from nnfmu.errors import check_options
from nnfmu.models import ModelConfig, architectures
from nnfmu.training import TrainConfig

#: ModelConfig fields a run sets: the architecture and the system's sizes, the seeds (members) or the members of
#: a search's ensemble, the data plan.
RUN_MODEL_FIELDS = ("arch", "n_u", "n_y", "members", "member_configs", "linear_order")
#: TrainConfig fields a run sets: its strategy, length, seed, dtype and validation split.
RUN_TRAIN_FIELDS = ("strategy", "epochs", "patience", "seed", "max_minutes", "dtype", "valid_fraction",
                    "valid_blocks")


def _fields(cls: type, run: tuple[str, ...]) -> list[tuple[str, object, dataclasses.Field]]:
    hints = typing.get_type_hints(cls)
    return [(f.name, hints[f.name], dataclasses.field(default=f.default) if f.default is not dataclasses.MISSING
             else dataclasses.field(default_factory=f.default_factory))
            for f in dataclasses.fields(cls) if f.name not in run]


_MODEL_FIELDS = tuple(name for name, _, _ in _fields(ModelConfig, RUN_MODEL_FIELDS))
_TRAIN_FIELDS = tuple(name for name, _, _ in _fields(TrainConfig, RUN_TRAIN_FIELDS))


class _HyperMethods:
    def model_config(self, arch: str, n_u: int, n_y: int) -> ModelConfig:
        """The config of ``arch`` (its record's config class) for a system with ``n_u`` inputs and ``n_y`` outputs.

        Fields that class does not have (another architecture's config) are left out.
        """
        cls = architectures.architecture(arch).get("config_class")
        known = {f.name for f in dataclasses.fields(cls)}
        return cls(arch=arch, n_u=n_u, n_y=n_y, **{k: getattr(self, k) for k in _MODEL_FIELDS if k in known})

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


Hyper = dataclasses.make_dataclass(
    "Hyper", _fields(ModelConfig, RUN_MODEL_FIELDS) + _fields(TrainConfig, RUN_TRAIN_FIELDS),
    bases=(_HyperMethods,), frozen=True, kw_only=True)
Hyper.__module__ = __name__  # for pickling (Ray ships it to its workers)
Hyper.__doc__ = f"""Hyperparameters of one architecture: the searched or preset part of a network and its training.

Attributes
----------
{', '.join(_MODEL_FIELDS)} :
    As in :class:`nnfmu.models.ModelConfig` (``layers``/``window`` None: the architecture's default).
{', '.join(_TRAIN_FIELDS)} :
    As in :class:`nnfmu.training.TrainConfig`.
"""


def per_arch(**hyper: Hyper) -> dict[str, Hyper]:
    """``{arch: Hyper}`` in the order given (the keywords name architectures; :class:`~nnfmu.study.budgets.Budget`
    checks them against the records)."""
    return dict(hyper)
