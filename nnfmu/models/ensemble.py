"""An ensemble of K networks of one config, simulated as one model (``ModelConfig.members = K``).

Each member keeps its own state; at every step all members predict ``y_{k+1}`` from their state
and the input, and their **mean** is the ensemble's prediction, fed back into every member as its
newest output (the one prediction of the free run)::

    x = [ x^(1) | ... | x^(K) ]                 each member's own flat state layout
    y_{k+1}^(i) = step_i(x^(i), u_k)            i = 1 .. K
    y_{k+1}     = mean_i y_{k+1}^(i)           then written into every x^(i) as its y_{k+1}

Averaging seeds removes much of the seed-to-seed variance of small-data training; feeding the
mean back (instead of running K free runs and averaging them afterwards) keeps it one model with
one state, so it exports as one FMU. The members share the normalisation of their training split.

The members are K networks of one config (seeds: :func:`nnfmu.training.train_seeds`) or, in a *mixed*
ensemble (``ModelConfig.member_configs``; the time-budget search keeps one), networks of different
architectures and widths that share their ports, init window, linear path and mode
(:data:`nnfmu.models.config.MEMBER_SHARED`).
"""

from __future__ import annotations

from typing import Mapping, Sequence

import torch
from torch import nn

from nnfmu.errors import ShapeError
from nnfmu.models import architectures
from nnfmu.models.base import StepModel
from nnfmu.models.config import MEMBER_SHARED, ModelConfig
from nnfmu.models.linear_path import LinearPathStepModel


def member_configs(config: ModelConfig) -> list[ModelConfig]:
    """The configs of an ensemble's members: its ``member_configs``, or itself with ``members=1``, K times."""
    if config.member_configs:
        return [ModelConfig.from_dict(d) for d in config.member_configs]
    return [config.replace(members=1)] * config.members


def single_model_class(config: ModelConfig) -> type:
    """The class of one network of ``config``: the architecture's own, or on a linear path (``linear_order > 0``)."""
    if getattr(config, "linear_order", 0):
        holds = architectures.architecture(config.arch).linear_path
        if not holds:
            raise ShapeError(f"a {config.arch} model cannot sit on a linear path (its record says "
                             "linear_path=False); set linear_order=0")
        if holds != "own":  # a model that holds its path itself is built by its own class
            return LinearPathStepModel
    return architectures.model_class(config.arch)


class EnsembleStepModel(StepModel):
    """``config.members`` networks: ``config.member_configs``, or ``config.replace(members=1)`` each (module doc)."""

    def __init__(self, config: ModelConfig, meta: Mapping | None = None):
        super().__init__(config, meta)
        if config.members < 2:
            raise ShapeError(f"an ensemble needs members >= 2, got {config.members}; build a single network instead")
        configs = member_configs(config)
        self.members = nn.ModuleList(single_model_class(c)(c, meta) for c in configs)
        self.check_sizes()

    @classmethod
    def from_members(cls, models: Sequence[StepModel]) -> "EnsembleStepModel":
        """The ensemble of trained networks of one meta and normalisation (weights copied).

        Networks of one config make a plain ensemble; networks of different configs a mixed one, when they
        share :data:`~nnfmu.models.config.MEMBER_SHARED`.
        """
        if len(models) < 2:
            raise ShapeError("an ensemble needs at least 2 trained networks")
        first = models[0]
        for m in models:
            if m.config.members != 1:
                raise ShapeError("an ensemble's members are single networks, not ensembles")
            for name in MEMBER_SHARED:
                if getattr(m.config, name) != getattr(first.config, name):
                    raise ShapeError(f"the networks differ in {name} ({getattr(first.config, name)!r} and "
                                     f"{getattr(m.config, name)!r}); the members of one ensemble share it")
        for name in ("u_mean", "u_std", "y_mean", "y_std"):
            if any(not torch.equal(getattr(m, name), getattr(first, name)) for m in models):
                raise ShapeError(f"the networks have different normalisation ({name}); train them on the same data")
        mixed = any(m.config != first.config for m in models)
        config = first.config.replace(members=len(models),
                                      member_configs=tuple(m.config.to_dict() for m in models) if mixed else ())
        ensemble = cls(config, first.meta).to(first.u_mean.dtype)
        for target, source in zip(ensemble.members, models):
            target.load_state_dict(source.state_dict())
        for name in ("u_mean", "u_std", "y_mean", "y_std"):
            getattr(ensemble, name).copy_(getattr(first, name))
        return ensemble

    def set_normalisation(self, stats) -> None:
        super().set_normalisation(stats)
        for m in self.members:
            m.set_normalisation(stats)

    def set_increment_scale(self, dy_std) -> None:
        super().set_increment_scale(dy_std)
        for m in self.members:
            m.set_increment_scale(dy_std)

    @property
    def n_x(self) -> int:
        return sum(m.n_x for m in self.members)

    def _parts(self, x: torch.Tensor) -> tuple[torch.Tensor, ...]:
        return torch.split(x, [m.n_x for m in self.members], dim=1)

    def init_norm(self, yn0: torch.Tensor, un0: torch.Tensor) -> torch.Tensor:
        return torch.cat([m.init_norm(yn0, un0) for m in self.members], dim=1)

    def init_window_norm(self, yn_win: torch.Tensor, un_win: torch.Tensor) -> torch.Tensor:
        return torch.cat([m.init_window_norm(yn_win, un_win) for m in self.members], dim=1)

    def step_norm(self, x: torch.Tensor, un: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        steps = [m.step_norm(part, un) for m, part in zip(self.members, self._parts(x))]
        yn = torch.stack([y for _, y in steps]).mean(0)
        return self.inject_y(torch.cat([x_next for x_next, _ in steps], dim=1), yn), yn

    def inject_y(self, x: torch.Tensor, yn: torch.Tensor) -> torch.Tensor:
        return torch.cat([m.inject_y(part, yn) for m, part in zip(self.members, self._parts(x))], dim=1)
