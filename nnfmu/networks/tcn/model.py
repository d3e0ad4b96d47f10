"""TCN step network: dilated causal convolutions over a window (step state: :mod:`nnfmu.networks.tcn.state`).

Layer ``i`` (``i = 0 .. layers-1``) is an ``nn.Conv1d`` with kernel size ``k``
and dilation ``2**i``, without padding ("valid"): each layer shortens the
sequence by ``(k-1) 2**i`` samples, so a window of exactly the receptive field
``L = 1 + (k-1)(2**layers - 1)`` yields one feature vector, the newest.
Causality comes from the window holding only past samples (and, for a whole
sequence, from padding on the left with the rest state). The convolutions
are evaluated as one matrix product of the stacked taps (im2col, channels
last) with the ``nn.Conv1d`` weights in their standard layout ``(H, C, k)``:
for the tiny per-step windows this is several times faster than
``conv1d``'s oneDNN path, and it is the same sum::

    h^(0) = dropout(act(conv_0(window)))
    h^(i) = h^(i-1)[..., cropped to the newest samples] + dropout(act(conv_i(h^(i-1))))   (i >= 1, residual)
    N     = head(h^(L-1)[..., newest])                                             head: Linear(H -> n_y)
    y_{k+1} = y_k + skip_scale * N   (skip=True),   N   (skip=False)

Teacher forcing evaluates these over the whole padded sequence in one call. The
step (and so the free run, a loop over it, and the exported FMU) is incremental:
each layer keeps a delay line of its past input columns in the state and
computes one new column per step (:mod:`nnfmu.networks.tcn.state`), the same sums.
"""

from __future__ import annotations

from typing import Mapping

import torch
from torch import nn
from torch.nn import functional as F

from nnfmu.errors import ConfigError
from nnfmu.models.activation import activation_module
from nnfmu.models.base import StepModel
from nnfmu.models.window import WindowStepModel
from nnfmu.networks.tcn import state as tcn_state
from nnfmu.networks.tcn.config import TCNConfig


class TCNStepModel(WindowStepModel):
    """Temporal convolutional network with residual dilated causal convolutions."""

    relative_window = False  # increment mode acts in the first layer, per column (:meth:`_conv`)

    def __init__(self, config: TCNConfig, meta: Mapping | None = None):
        if not isinstance(config, TCNConfig):
            raise ConfigError(f"TCNStepModel needs a TCNConfig, got {type(config).__name__}")
        super().__init__(config, meta)
        self.convs = nn.ModuleList(
            nn.Conv1d(config.n_in if i == 0 else config.hidden, config.hidden, config.kernel_size, dilation=2 ** i)
            for i in range(config.layers)
        )
        self.activation = activation_module(config.activation)
        self.dropout = nn.Dropout(config.dropout)
        self.head = nn.Linear(config.hidden, config.n_y)
        self.check_sizes()

    def _conv(self, i: int, h: torch.Tensor) -> torch.Tensor:
        """Valid dilated convolution of layer ``i`` over ``h`` (B, T_in, C) channels last -> (B, T_in - (k-1)d, H).

        In increment mode the first layer's taps are relative to their newest (:func:`tcn_state.relative_taps`)."""
        conv = self.convs[i]
        k, d = conv.kernel_size[0], conv.dilation[0]
        n_out = h.shape[1] - (k - 1) * d
        shifted = [h[:, j * d:j * d + n_out] for j in range(k)]
        if i == 0 and self.config.increment:  # (B, n_out, k, C) made relative, then as below
            taps = tcn_state.relative_taps(torch.stack(shifted, dim=2), self.config.n_y).transpose(2, 3)
        else:
            taps = torch.stack(shifted, dim=3)  # (B, n_out, C, k)
        # (B, n_out, C*k) channel-major matches the (H, C, k) weight viewed as (H, C*k): no weight copy
        return F.linear(taps.reshape(*taps.shape[:2], -1), conv.weight.view(conv.out_channels, -1), conv.bias)

    def _features(self, seq: torch.Tensor) -> torch.Tensor:
        """``seq`` (B, T + L - 1, C) -> features (B, T, H) of the T newest positions."""
        h = seq
        drop = self.training and self.dropout.p > 0  # skip the no-op module call in the hot loop
        for i in range(len(self.convs)):
            out = self.activation(self._conv(i, h))
            out = self.dropout(out) if drop else out
            h = out if i == 0 else h[:, h.shape[1] - out.shape[1]:] + out
        return h

    def _predict_windows(self, window: torch.Tensor) -> torch.Tensor:
        return self.head(self._features(window)[:, -1])

    # ---- the incremental step (state layout: nnfmu.networks.tcn.state) -------------------------
    @property
    def n_x(self) -> int:
        return tcn_state.state_size(self.config)

    def init_norm(self, yn0: torch.Tensor, un0: torch.Tensor) -> torch.Tensor:
        return tcn_state.init(self, yn0, un0)

    def step_norm(self, x: torch.Tensor, un: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        return tcn_state.step(self, x, un)

    def inject_y(self, x: torch.Tensor, yn: torch.Tensor) -> torch.Tensor:
        return torch.cat([yn, x[:, self.config.n_y:]], dim=1)

    def free_run_norm(self, un: torch.Tensor, yn0: torch.Tensor, x0: torch.Tensor | None = None,
                       output=None) -> torch.Tensor:
        return StepModel.free_run_norm(self, un, yn0, x0, output)  # the loop over the incremental step

    def teacher_forced_norm(self, un: torch.Tensor, yn_meas: torch.Tensor,
                             x0: torch.Tensor | None = None) -> torch.Tensor:
        if x0 is not None:  # an init window's delay lines, not samples to pad the sequence with
            return StepModel.teacher_forced_norm(self, un, yn_meas, x0)
        return super().teacher_forced_norm(un, yn_meas)

    def state_from_window(self, yn_window: torch.Tensor, un_window: torch.Tensor) -> torch.Tensor:
        self._check_window(yn_window, un_window)
        return tcn_state.from_window(self, torch.cat([yn_window[:, :-1], un_window], dim=2), yn_window[:, -1])

    def _predict_sequence(self, padded: torch.Tensor) -> torch.Tensor:
        return self.head(self._features(padded))
