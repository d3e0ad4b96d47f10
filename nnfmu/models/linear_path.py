"""A network on a linear path: the identified linear model plus a learned correction that starts at zero.

``ModelConfig.linear_order = n_z > 0`` puts any of the five networks (``self.net``, built with
``skip=False``) on a linear state-space model of ``n_z`` states, in normalised units::

    n_k, h_{k+1} = net(h_k, y_k, u_k)                   the network's raw output (n_y) and own state
    z_{k+1} = A z_k + B u_k + b + G n_k                 linear state (n_z); G (n_z, n_y) starts at zero
    y_{k+1} = C z_{k+1} + d + alpha * n_k               alpha (n_y) starts at zero

The state is ``x = [ h (the network's own layout; its fed-back output is y) | z ]``. ``A, B, b, C, d``
are the identified linear baseline (:func:`nnfmu.linear.identify_linear`, moved into the network's
normalised units by :func:`nnfmu.training.linear_start.start_linear_path`) and stay fixed: trained with the network
at its learning rate, they moved the slider's validation free runs from 0.31 to 2-14 within 150
epochs. With ``G = 0`` and ``alpha = 0`` the untrained model *is* the linear model, and training starts
at its free-run error; the trainer keeps epoch 0 unless validation improves, so the kept weights are
never worse on validation. The network corrects the linear state update (``G n``: what an integrating
plant integrates, e.g. friction) and the output (``alpha n``). For a recurrent network this is a
neural state-space model ``[z; h]+ = [A z + B u + G n(h, y, u); f(h, y, u)]``, ``y = C z + alpha n``
with a linear initialisation; for the MLP and TCN the correction is a NARX network of their window.

``init(y0, u0)`` sets the network's state as without the path, and ``z0`` by the linear model's
``estimate`` rule from the newest sample (:func:`nnfmu.linear.init_gains`), so that ``C z0 + d``
reproduces ``y0`` and the unseen states start at equilibrium. With an init window the network's
encoder sees the window; ``z0`` uses its newest sample.
"""

from __future__ import annotations

from typing import Mapping

import numpy as np
import torch
from torch import nn

from nnfmu.errors import ShapeError
from nnfmu.models import architectures
from nnfmu.models.base import StepModel
from nnfmu.models.config import ModelConfig


def inner_config(config: ModelConfig) -> ModelConfig:
    """The network on the path: the same architecture and sizes, raw output (no skip, no increment)."""
    return config.replace(linear_order=0, skip=False, increment=False, members=1)


class LinearPathStepModel(StepModel):
    """A network of ``inner_config(config)`` on a linear path of ``config.linear_order`` states (module docstring)."""

    def __init__(self, config: ModelConfig, meta: Mapping | None = None):
        super().__init__(config, meta)
        if config.linear_order < 1:
            raise ShapeError(f"a linear path needs linear_order >= 1, got {config.linear_order}")
        inner = inner_config(config)
        self.net = architectures.model_class(inner.arch)(inner, meta)
        n, n_u, n_y = config.linear_order, config.n_u, config.n_y
        for name, shape in (("lin_A", (n, n)), ("lin_B", (n, n_u)), ("lin_b", (n,)), ("lin_C", (n_y, n)),
                            ("lin_d", (n_y,))):
            self.register_buffer(name, torch.zeros(shape))  # the identified linear model: held fixed
        self.alpha = nn.Parameter(torch.zeros(n_y))  # the correction of the output: zero at the start
        self.lin_G = nn.Parameter(torch.zeros(n, n_y))  # the correction of the linear state: zero at the start
        self.register_buffer("lin_Ky", torch.zeros(n, n_y))  # z0 = Ky yn0 + Ku un0 + k0 (normalised units)
        self.register_buffer("lin_Ku", torch.zeros(n, n_u))
        self.register_buffer("lin_k0", torch.zeros(n))
        self.check_sizes()

    # ---- the linear model, in normalised units ---------------------------------------------------
    #: The arrays :meth:`set_path` takes: the fixed linear model, its initial-state rule and the correction's gains.
    PATH_ARRAYS = ("lin_A", "lin_B", "lin_b", "lin_C", "lin_d", "lin_Ky", "lin_Ku", "lin_k0", "lin_G", "alpha")

    def set_path(self, values: Mapping) -> None:
        """Set every array of :data:`PATH_ARRAYS` (normalised units; see the module docstring).

        :func:`nnfmu.training.linear_start.start_linear_path` computes them from an identified linear model.
        """
        missing = set(self.PATH_ARRAYS) - set(values)
        if missing:
            raise ShapeError(f"set_path needs {', '.join(sorted(missing))} too")
        with torch.no_grad():
            for name in self.PATH_ARRAYS:
                target = getattr(self, name)
                value = torch.as_tensor(np.asarray(values[name], dtype=np.float64))
                if tuple(value.shape) != tuple(target.shape) or not torch.isfinite(value).all():
                    raise ShapeError(f"{name} must be finite with shape {tuple(target.shape)}, got "
                                     f"{tuple(value.shape)}")
                target.copy_(value)

    def set_normalisation(self, stats) -> None:
        super().set_normalisation(stats)
        self.net.set_normalisation(stats)

    # ---- the step ------------------------------------------------------------------------------
    @property
    def n_x(self) -> int:
        return self.net.n_x + self.config.linear_order

    def _split(self, x: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        return x[:, :self.net.n_x], x[:, self.net.n_x:]

    def _z0(self, yn0: torch.Tensor, un0: torch.Tensor) -> torch.Tensor:
        return yn0 @ self.lin_Ky.T + un0 @ self.lin_Ku.T + self.lin_k0

    def init_norm(self, yn0: torch.Tensor, un0: torch.Tensor) -> torch.Tensor:
        return torch.cat([self.net.init_norm(yn0, un0), self._z0(yn0, un0)], dim=1)

    def init_window_norm(self, yn_win: torch.Tensor, un_win: torch.Tensor) -> torch.Tensor:
        return torch.cat([self.net.init_window_norm(yn_win, un_win), self._z0(yn_win[:, -1], un_win[:, -1])], dim=1)

    def step_norm(self, x: torch.Tensor, un: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        h, z = self._split(x)
        h_next, n = self.net.step_norm(h, un)
        z_next = z @ self.lin_A.T + un @ self.lin_B.T + self.lin_b + n @ self.lin_G.T
        yn = z_next @ self.lin_C.T + self.lin_d + self.alpha * n
        return torch.cat([self.net.inject_y(h_next, yn), z_next], dim=1), yn

    def free_run_norm(self, un: torch.Tensor, yn0: torch.Tensor, x0: torch.Tensor | None = None,
                       output=None) -> torch.Tensor:
        """The network's own (fast) free run, its every raw output turned into the path's output on the way.

        Equal to the loop over :meth:`step_norm`; the network's loop keeps its own state layout (the MLP's window
        tensor: 2 concatenations a step instead of packing ``[h | z]``).
        """
        h0, z = (None, self._z0(yn0, un[:, 0])) if x0 is None else self._split(x0)
        inputs = iter(un[:, :-1].unbind(1))

        def path_output(n: torch.Tensor) -> torch.Tensor:
            nonlocal z
            z = z @ self.lin_A.T + next(inputs) @ self.lin_B.T + self.lin_b + n @ self.lin_G.T
            yn = z @ self.lin_C.T + self.lin_d + self.alpha * n
            return yn if output is None else output(yn)

        self.net.feedback_noise = self.feedback_noise  # the network's loop disturbs what it feeds back
        try:
            return self.net.free_run_norm(un, yn0, h0, path_output)
        finally:
            self.net.feedback_noise = 0.0

    def inject_y(self, x: torch.Tensor, yn: torch.Tensor) -> torch.Tensor:
        h, z = self._split(x)
        return torch.cat([self.net.inject_y(h, yn), z], dim=1)


def y_slot(model: StepModel) -> list[int]:
    """Positions in the flat state where ``model.inject_y`` writes the fed-back output, in output order."""
    n_y, dtype = model.config.n_y, model.u_mean.dtype
    with torch.no_grad():
        probe = torch.arange(1, n_y + 1, dtype=dtype)[None]
        x = model.inject_y(torch.zeros(1, model.n_x, dtype=dtype), probe)[0].cpu().numpy()
    return [int(np.flatnonzero(x == j + 1)[0]) for j in range(n_y)]
