"""``NodeStepModel``: the neural ODE as a :class:`~nnfmu.hybrid.HybridStepModel` on its generated zero physics.

Everything runs as in the hybrid (RK4 of ``ode + delta``, free run, export); three things differ:

- the physics' parameters ``[y_mean, y_std]`` (n_p = 2 n_y) are the model's output normalisation buffers
  (:meth:`physics_parameters`), so the states are the outputs in standard deviations however the data are
  scaled, and a checkpoint or FMU holds them with the data's units (:meth:`physics_variables`);
- the correction's scale is ``1 / (time_scale * Ts)`` with the data's ``Ts`` (the generated physics counts
  time in samples), so ``xdot = N(x, u) / (time_scale * Ts)`` on every state;
- the physics takes the data's names and units, so there is no unit check against it.
"""

from __future__ import annotations

from typing import Mapping

import torch

from nnfmu.errors import ShapeError
from nnfmu.hybrid.model import HybridStepModel
from nnfmu.node.config import NodeConfig
from nnfmu.physics import PhysicsSystem
from nnfmu.system import Variable

__all__ = ["NodeStepModel"]


class NodeStepModel(HybridStepModel):
    """The neural ODE (see :mod:`nnfmu.node`); state ``x`` (B, n_states) in output-normalised units."""

    def __init__(self, config: NodeConfig, meta: Mapping | None = None):
        if not isinstance(config, NodeConfig):
            raise ShapeError(f"expected a NodeConfig, got {type(config).__name__}")
        super().__init__(config, meta)
        self._scatter = self._scatter / self.Ts  # correction_time = time_scale samples, in seconds

    def _check_units(self, system: PhysicsSystem) -> None:
        """Nothing to check: the generated physics has no units of its own (the data's apply)."""

    def physics_parameters(self) -> torch.Tensor:
        """``[y_mean, y_std]`` (2 n_y,) in float64: the output normalisation, which the physics' output map uses."""
        return torch.cat([self.y_mean, self.y_std]).to(torch.float64)

    def physics_variables(self) -> tuple[Variable, ...]:
        """The output offsets and scales as FMU parameters, in the outputs' units."""
        channels = list(self.meta["outputs"]) * 2
        values = self.physics_parameters().detach().tolist()
        return tuple(Variable(v.name, ch.get("unit", ""), f"{'offset' if i < self.config.n_y else 'scale'} of "
                              f"output {ch['name']!r} (the neural ODE's state is (y - offset) / scale)", value)
                     for i, (v, ch, value) in enumerate(zip(self.physics.parameters, channels, values)))
