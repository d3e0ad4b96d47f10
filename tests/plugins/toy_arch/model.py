"""The toy network: a leaky one-layer recurrent cell on the public base classes of nnfmu.models.

In normalised units, with state ``x = [y_k (n_y) | h_k (hidden)]``::

    h_{k+1} = leak * h_k + (1 - leak) * tanh(W [h_k, y_k, u_k] + b)
    y_{k+1} = y_k + skip_scale * (V h_{k+1} + c)        (skip=True; the raw V h + c without it)
"""

from __future__ import annotations

from dataclasses import dataclass

import torch
from torch import nn

from nnfmu.errors import ConfigError, ShapeError
from nnfmu.models import ModelConfig, StepModel


@dataclass(frozen=True, kw_only=True)
class ToyConfig(ModelConfig):
    """:class:`~nnfmu.models.ModelConfig` for ``arch="toy"``, plus ``leak`` in [0, 1)."""

    arch: str = "toy"
    leak: float = 0.0

    def __post_init__(self) -> None:
        super().__post_init__()
        if not 0.0 <= float(self.leak) < 1.0:
            raise ConfigError(f"the toy's leak must be in [0, 1), got {self.leak!r}")
        object.__setattr__(self, "leak", float(self.leak))

    def resolve_window(self) -> int:
        if self.window not in (None, 1):
            raise ShapeError(f"the toy sees one sample per step, so window must be 1, got {self.window}")
        return 1


class ToyStepModel(StepModel):
    """The toy cell (module docstring); the base class gives normalisation, loops and checks."""

    def __init__(self, config: ToyConfig, meta=None):
        super().__init__(config, meta)
        self.cell = nn.Linear(config.hidden + config.n_y + config.n_u, config.hidden)
        self.readout = nn.Linear(config.hidden, config.n_y)
        self.check_sizes()

    @property
    def n_x(self) -> int:
        return self.config.n_y + self.config.hidden

    def init_norm(self, yn0: torch.Tensor, un0: torch.Tensor) -> torch.Tensor:
        return torch.cat([yn0, yn0.new_zeros(len(yn0), self.config.hidden)], dim=1)

    def step_norm(self, x: torch.Tensor, un: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        c = self.config
        yn, h = x[:, :c.n_y], x[:, c.n_y:]
        h_next = c.leak * h + (1.0 - c.leak) * torch.tanh(self.cell(torch.cat([h, self.y_input(yn), un], dim=1)))
        yn_next = self.apply_skip(yn, self.readout(h_next))
        return torch.cat([yn_next, h_next], dim=1), yn_next

    def inject_y(self, x: torch.Tensor, yn: torch.Tensor) -> torch.Tensor:
        return torch.cat([yn, x[:, self.config.n_y:]], dim=1)
