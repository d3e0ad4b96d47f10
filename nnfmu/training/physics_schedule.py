"""How a model's physical parameters train beside its network: ``joint`` or ``staged``.

A hybrid (:mod:`nnfmu.hybrid`) trains the physical parameters its config names (``train_physics``) with the
correction network. ``TrainConfig.physics_schedule`` says when:

- ``joint``: from the first step, at the network's learning rate;
- ``staged``: frozen first, so the correction learns what the given physics lacks; then joint, the physical
  parameters at :data:`STAGED_LR` times the learning rate. The frozen stage ends at the first of: half the
  epochs, half the ``max_minutes`` budget, or the early-stopping patience running out (which then restarts).

Freezing them for the whole run is ``train_physics=()`` (``--train-physics none``). A model without physical
parameters trains as it would without a schedule.
"""

from __future__ import annotations

import time

from torch import nn

from nnfmu.training.config import PHYSICS_SCHEDULES  # noqa: F401  (the choices, declared with the config)

#: The physical parameters' learning rate in the joint stage of ``staged``, as a fraction of ``lr``.
STAGED_LR = 0.1


def physical_parameters(model: nn.Module) -> list[nn.Parameter]:
    """The model's trained physical parameters (a hybrid's ``physics_log_scale``), or [] (a network)."""
    theta = getattr(model, "physics_log_scale", None)
    return [theta] if isinstance(theta, nn.Parameter) and theta.numel() else []


class PhysicsSchedule:
    """The optimiser's parameter groups and the stage of one training run."""

    def __init__(self, model: nn.Module, schedule: str):
        self.staged = schedule == "staged" and bool(physical_parameters(model))
        self.physics = physical_parameters(model) if self.staged else []
        self.joint = not self.staged
        self._apply()

    def groups(self, model: nn.Module):
        """``model.parameters()`` (joint: one group, as before schedules), else the network's and the physics'
        groups, the latter with its ``lr_scale``."""
        if not self.staged:
            return model.parameters()
        ids = {id(p) for p in self.physics}
        return [{"params": [p for p in model.parameters() if id(p) not in ids], "lr_scale": 1.0},
                {"params": self.physics, "lr_scale": STAGED_LR}]

    def _apply(self) -> None:
        for p in self.physics:  # frozen: no gradient, so neither AdamW nor the gradient clipping sees them
            p.requires_grad_(self.joint)

    def due(self, epoch: int, epochs: int, budget: tuple[float, float] | None, patience_out: bool) -> bool:
        """Whether the frozen stage ends now: half the ``epochs`` done, half the ``budget`` (start, deadline;
        :func:`time.monotonic` seconds) spent, or the patience out."""
        if self.joint:
            return False
        half_time = budget is not None and time.monotonic() >= (budget[0] + budget[1]) / 2
        return patience_out or half_time or 2 * epoch >= epochs

    def start_joint(self) -> None:
        self.joint = True
        self._apply()

    def state(self) -> dict:
        return {"physics_joint": self.joint}

    def restore(self, state: dict) -> None:
        if self.staged and state.get("physics_joint"):
            self.start_joint()
