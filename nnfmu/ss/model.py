"""The subspace-encoder state-space network (SUBNET: Beintema, Schoukens and Toth, Automatica 2023).

In normalised units, with the latent state ``z`` (``n_x = config.n_states``)::

    z_0     = K_y y_0 + K_u u_0 + k_0 + E(window)          encoder: the init window's N samples
    z_{k+1} = A z_k + B u_k + b + f(z_k, u_k)              state map
    y_{k+1} = C z_{k+1} + d + h(z_{k+1})                   output map (no feedthrough from u)

``A, B, b, C, d`` and the initial-state rule ``K_y, K_u, k_0`` are the identified linear baseline
(:func:`nnfmu.training.linear_start.start_linear_path`, its states scaled to unit RMS), held fixed; the
states beyond the linear order (``states > linear_order``) have none. ``f`` and ``h`` are MLPs of
``layers`` hidden layers of ``hidden`` units; ``E`` is the learned encoder of :mod:`nnfmu.models.encoder`
on the flattened window. On a linear path the last layers of ``f``, ``h`` and ``E`` start at zero, so the
untrained network *is* the linear model (its free run to rounding, in torch, CasADi and the FMU) and
training learns a correction; ``f`` and ``h`` are then read through ``1 / hidden`` (:attr:`SSStepModel.scale`),
so that one optimiser step (Adam moves every weight by about the learning rate) moves the state by about the
learning rate, as the other networks' path gains do, and not ``hidden`` times that: unscaled, the first steps
threw the slider's integrating state off (a training loss of 236 in the first epoch, never recovered).
Without a path (``linear_order = 0``) the linear part is zero and ``f``, ``h`` start as ordinary random MLPs
read at scale 1 (SUBNET's own form).

The flat state is ``x = [y_k (n_y) | z_k (n_x)]``: the newest output is kept beside ``z`` so that
ensembles and teacher forcing find it where every network keeps it, but the step does not read it.
Training is the truncated simulation loss of SUBNET: free runs over windows cut from the records, each
starting from the encoder's estimate (``nnfmu train`` chooses the windows' length from the data).
"""

from __future__ import annotations

from typing import Mapping

import numpy as np
import torch
from torch import nn
from torch.nn import functional as F

from nnfmu.errors import ShapeError
from nnfmu.models import StepModel
from nnfmu.models.encoder import encoder_input, make_encoder
from nnfmu.models.activation import activation_module
from nnfmu.ss.compiled import compiled_states
from nnfmu.ss.config import SSConfig


def _mlp(n_in: int, n_out: int, config: SSConfig, zero_last: bool) -> nn.Sequential:
    """``layers`` x (Linear(. -> hidden), activation), then Linear(hidden -> n_out), zero when ``zero_last``."""
    modules: list[nn.Module] = []
    for _ in range(config.layers):
        modules += [nn.Linear(n_in, config.hidden), activation_module(config.activation)]
        n_in = config.hidden
    modules.append(nn.Linear(n_in, n_out))
    if zero_last:
        nn.init.zeros_(modules[-1].weight)
        nn.init.zeros_(modules[-1].bias)
    return nn.Sequential(*modules)


def _run(seq: nn.Sequential, v: torch.Tensor) -> torch.Tensor:
    """``seq(v)`` without the per-module call overhead (the free run's hot loop)."""
    for module in seq:
        v = F.linear(v, module.weight, module.bias) if type(module) is nn.Linear else module(v)
    return v


class SSStepModel(StepModel):
    """``x = [y_k | z_k]``; ``f``, ``h``, ``encoder`` and the fixed linear model (module docstring)."""

    takes_feedback_noise = False  # the output is not fed back: nothing for feedback noise to disturb

    #: The linear model's arrays that :meth:`set_path` takes (as :class:`~nnfmu.models.LinearPathStepModel`'s).
    PATH_ARRAYS = ("lin_A", "lin_B", "lin_b", "lin_C", "lin_d", "lin_Ky", "lin_Ku", "lin_k0")

    def __init__(self, config: SSConfig, meta: Mapping | None = None):
        super().__init__(config, meta)
        if not isinstance(config, SSConfig):
            raise ShapeError(f"SSStepModel needs an SSConfig, got {type(config).__name__}")
        s, n_u, n_y, on_path = config.n_states, config.n_u, config.n_y, config.linear_order > 0
        #: The factor ``f`` and ``h`` are read through: ``1 / hidden`` on a linear path (module docstring), else 1.
        self.scale = 1.0 / config.hidden if on_path else 1.0
        self.f = _mlp(s + n_u, s, config, zero_last=on_path)
        self.h = _mlp(s, n_y, config, zero_last=on_path)
        self.encoder = make_encoder(config, s)
        for name, shape in (("lin_A", (s, s)), ("lin_B", (s, n_u)), ("lin_b", (s,)), ("lin_C", (n_y, s)),
                            ("lin_d", (n_y,)), ("lin_Ky", (s, n_y)), ("lin_Ku", (s, n_u)), ("lin_k0", (s,))):
            self.register_buffer(name, torch.zeros(shape))  # the identified linear model: held fixed
        self.check_sizes()

    def set_path(self, values: Mapping) -> None:
        """Set the linear model from :func:`~nnfmu.training.linear_start.path_arrays` (normalised units).

        Its ``linear_order`` states fill the first rows and columns; the states beyond them keep zeros.
        """
        n = self.config.linear_order
        blocks = {"lin_A": (n, n), "lin_B": (n, None), "lin_b": (n,), "lin_C": (None, n), "lin_d": (None,),
                  "lin_Ky": (n, None), "lin_Ku": (n, None), "lin_k0": (n,)}
        missing = set(self.PATH_ARRAYS) - set(values)
        if missing:
            raise ShapeError(f"set_path needs {', '.join(sorted(missing))} too")
        with torch.no_grad():
            for name, block in blocks.items():
                target = getattr(self, name)
                index = tuple(slice(0, k) for k in block)
                value = torch.as_tensor(np.asarray(values[name], dtype=np.float64))
                if tuple(value.shape) != tuple(target[index].shape) or not torch.isfinite(value).all():
                    raise ShapeError(f"{name} must be finite with shape {tuple(target[index].shape)}, got "
                                     f"{tuple(value.shape)}")
                target.zero_()
                target[index] = value.to(target.dtype)

    # ---- the step ------------------------------------------------------------------------------
    @property
    def n_x(self) -> int:
        return self.config.n_y + self.config.n_states

    def _z0(self, yn0: torch.Tensor, un0: torch.Tensor) -> torch.Tensor:
        return yn0 @ self.lin_Ky.T + un0 @ self.lin_Ku.T + self.lin_k0

    def init_norm(self, yn0: torch.Tensor, un0: torch.Tensor) -> torch.Tensor:
        c = self.config
        return self.init_window_norm(yn0[:, None].expand(-1, c.init_window, -1),
                                      un0[:, None].expand(-1, c.init_window, -1))

    def init_window_norm(self, yn_win: torch.Tensor, un_win: torch.Tensor) -> torch.Tensor:
        yn0 = yn_win[:, -1]
        z0 = self._z0(yn0, un_win[:, -1]) + _run(self.encoder, encoder_input(yn_win, un_win, relative=False))
        return torch.cat([yn0, z0], dim=1)

    def _state_next(self, z: torch.Tensor, un: torch.Tensor) -> torch.Tensor:
        return z @ self.lin_A.T + un @ self.lin_B.T + self.lin_b + self.scale * _run(self.f, torch.cat([z, un], dim=1))

    def _output(self, z: torch.Tensor) -> torch.Tensor:
        return z @ self.lin_C.T + self.lin_d + self.scale * _run(self.h, z)

    def step_norm(self, x: torch.Tensor, un: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        z_next = self._state_next(x[:, self.config.n_y:], un)
        yn = self._output(z_next)
        return torch.cat([yn, z_next], dim=1), yn

    def inject_y(self, x: torch.Tensor, yn: torch.Tensor) -> torch.Tensor:
        return torch.cat([yn, x[:, self.config.n_y:]], dim=1)

    def free_run_norm(self, un: torch.Tensor, yn0: torch.Tensor, x0: torch.Tensor | None = None,
                       output=None) -> torch.Tensor:
        """The loop over the state alone, the outputs of all steps in one call afterwards (none is fed back).

        Equal to the loop over :meth:`step_norm`; ``output`` (an ensemble's mean) is called per step.
        """
        x = self.init_norm(yn0, un[:, 0]) if x0 is None else x0
        z = x[:, self.config.n_y:]
        if output is not None:
            ys = [yn0]
            for k in range(un.shape[1] - 1):
                z = self._state_next(z, un[:, k])
                ys.append(output(self._output(z)))
            return torch.stack(ys, dim=1)
        if un.shape[1] < 2:
            return yn0[:, None]
        return torch.cat([yn0[:, None], self._output(self._states(z, un[:, :-1]))], dim=1)

    def _states(self, z: torch.Tensor, un: torch.Tensor) -> torch.Tensor:
        """``z_1 .. z_T`` (B, T, n_x) from ``z_0`` (B, n_x) and ``u_0 .. u_{T-1}`` (B, T, n_u).

        The same sums as :meth:`_state_next`, arranged for the loop: the input's share of ``A z + B u + b`` and
        of ``f``'s first layer for all steps at once, and ``z``'s shares of both in one product per step; the loop
        itself is compiled C where it applies (:mod:`nnfmu.ss.compiled`).
        """
        first, s = self.f[0], self.config.n_states
        drive = un @ self.lin_B.T + self.lin_b  # (B, T, n_x)
        pre = un @ first.weight[:, s:].T + first.bias  # (B, T, hidden)
        loop = compiled_states(self) if type(self) is SSStepModel else None  # a subclass may step otherwise
        if loop is not None:  # the same loop in C (nnfmu/ss/state_loop.c)
            return loop(z, drive, pre)
        joint = torch.cat([self.lin_A.T, first.weight[:, :s].T], dim=1)  # z -> [A z | W_z z]
        rest = self.f[1:]
        zs = []
        for drive_k, pre_k in zip(drive.unbind(1), pre.unbind(1)):  # unbind: one backward for all the steps' slices
            zz = z @ joint
            z = zz[:, :s] + drive_k + self.scale * _run(rest, zz[:, s:] + pre_k)
            zs.append(z)
        return torch.stack(zs, dim=1)
