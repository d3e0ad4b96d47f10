"""RNN, LSTM and GRU step networks with output feedback.

The network's input at step k is ``[y_k, u_k]`` (normalised). Each of the
``layers`` stacked layers is a one-layer ``nn.RNN`` / ``nn.LSTM`` / ``nn.GRU``
in PyTorch's standard weight layout (``weight_ih_l0``, ``weight_hh_l0``,
``bias_ih_l0``, ``bias_hh_l0``; gate order i, f, g, o for the LSTM and r, z, n
for the GRU), followed by a linear readout of the last layer's hidden state::

    h_k^(1..L) = cells([y_k, u_k], h_{k-1}^(1..L))
    y_{k+1}    = y_k + skip_scale * readout(h_k^(L))      (skip=True)
    y_{k+1}    = readout(h_k^(L))                         (skip=False)

Flat state layout, all in normalised units (what the FMU carries)::

    x = [ y_k (n_y) | h^(1) (hidden) | ... | h^(L) (hidden) | c^(1) | ... | c^(L) ]   (c: LSTM only)

``init(y0, u0)`` sets ``y_k = y0`` and all hidden and cell states to zero; with an init window
(``init_window > 1``) a learned encoder maps the window to them (:mod:`nnfmu.models.encoder`).
In increment mode the cells see ``y_k`` relative to itself, i.e. not at all: the hidden state carries
the dynamics and the output integrates the readout.
Dropout (training only) acts on each layer's output, between layers and before the readout.
The sequence calls use the fused ``nn.GRU`` etc. for teacher forcing and the
same cell functions as :meth:`step` for the free run.
"""

from __future__ import annotations

from typing import Mapping

import torch
from torch import nn
from torch.nn import functional as F

from nnfmu.errors import ConfigError
from nnfmu.models.base import StepModel
from nnfmu.models.encoder import encoder_input, make_encoder
from nnfmu.networks.recurrent.config import RecurrentConfig


class RecurrentStepModel(StepModel):
    """RNN / LSTM / GRU with output feedback; ``config.arch`` picks the cell."""

    def __init__(self, config: RecurrentConfig, meta: Mapping | None = None):
        if not isinstance(config, RecurrentConfig):
            raise ConfigError(f"RecurrentStepModel needs a RecurrentConfig, got {type(config).__name__}")
        super().__init__(config, meta)
        self.rnn_layers = nn.ModuleList(
            _make_layer(config, config.n_in if i == 0 else config.hidden) for i in range(config.layers)
        )
        self.dropout = nn.Dropout(config.dropout)
        self.readout = nn.Linear(config.hidden, config.n_y)
        if config.init_window > 1:
            self.encoder = make_encoder(config, self.n_x - config.n_y)
        self.check_sizes()

    @property
    def is_lstm(self) -> bool:
        return self.config.arch == "lstm"

    @property
    def n_x(self) -> int:
        c = self.config
        return c.n_y + c.layers * c.hidden * (2 if self.is_lstm else 1)

    # ---- state packing -----------------------------------------------------------------------
    def _split(self, x: torch.Tensor) -> tuple[torch.Tensor, list, list]:
        c = self.config
        yn = x[:, :c.n_y]
        # contiguous copies: matrix products on strided views can round differently
        chunks = [h.contiguous() for h in torch.split(x[:, c.n_y:], c.hidden, dim=1)]
        hs, cs = (chunks[:c.layers], chunks[c.layers:]) if self.is_lstm else (chunks, [])
        return yn, hs, cs

    def _pack(self, yn: torch.Tensor, hs: list, cs: list) -> torch.Tensor:
        return torch.cat([yn, *hs, *cs], dim=1)

    # ---- the core ----------------------------------------------------------------------------
    def _weights(self) -> tuple:
        """Per-layer ``(cell function, weights)`` and the readout, fetched once per rollout (per-step overhead)."""
        if self.is_lstm:
            cell = torch.lstm_cell
        elif self.config.arch == "gru":
            cell = torch.gru_cell
        else:
            cell = torch.rnn_relu_cell if self.config.activation == "relu" else torch.rnn_tanh_cell
        layers = [(m.weight_ih_l0, m.weight_hh_l0, m.bias_ih_l0, m.bias_hh_l0) for m in self.rnn_layers]
        return cell, layers, (self.readout.weight, self.readout.bias)

    def _cell_step(self, yn, un, hs: list, cs: list, weights: tuple) -> tuple[torch.Tensor, list, list]:
        """One step on unpacked states; shared by :meth:`step_norm` and the free run."""
        cell, layers, readout = weights
        drop = self.training and self.config.dropout > 0
        inp = torch.cat([self.y_input(yn), un], dim=1)
        new_h, new_c = [], []
        for i, w in enumerate(layers):
            if self.is_lstm:
                h, c = cell(inp, (hs[i], cs[i]), *w)
                new_c.append(c)
            else:
                h = cell(inp, hs[i], *w)
            new_h.append(h)
            inp = F.dropout(h, self.config.dropout) if drop else h
        return self.apply_skip(yn, F.linear(inp, *readout)), new_h, new_c

    def init_norm(self, yn0: torch.Tensor, un0: torch.Tensor) -> torch.Tensor:
        zeros = yn0.new_zeros(yn0.shape[0], self.n_x - self.config.n_y)
        return torch.cat([yn0, zeros], dim=1)

    def init_window_norm(self, yn_win: torch.Tensor, un_win: torch.Tensor) -> torch.Tensor:
        if self.config.init_window == 1:
            return self.init_norm(yn_win[:, -1], un_win[:, -1])
        hidden = self.encoder(encoder_input(yn_win, un_win, self.config.increment))
        return torch.cat([yn_win[:, -1], hidden], dim=1)

    def step_norm(self, x: torch.Tensor, un: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        yn, hs, cs = self._split(x)
        yn_next, hs, cs = self._cell_step(yn, un, hs, cs, self._weights())
        return self._pack(yn_next, hs, cs), yn_next

    def inject_y(self, x: torch.Tensor, yn: torch.Tensor) -> torch.Tensor:
        return torch.cat([yn, x[:, self.config.n_y:]], dim=1)

    def free_run_norm(self, un: torch.Tensor, yn0: torch.Tensor, x0: torch.Tensor | None = None,
                       output=None) -> torch.Tensor:
        """Free run without packing the state each step (same operations as :meth:`step_norm`); ``output`` as in
        :meth:`StepModel.free_run_norm`."""
        _, hs, cs = self._split(self.init_norm(yn0, un[:, 0]) if x0 is None else x0)
        yn, ys, weights = yn0, [yn0], self._weights()
        noisy_increments = bool(self.feedback_noise and self.training and self.config.increment)
        for un_k in un[:, :-1].unbind(1):
            fed = self._feedback(yn)
            y_next, hs, cs = self._cell_step(fed, un_k, hs, cs, weights)
            yn = self._unshifted(y_next, fed, yn) if noisy_increments else y_next
            yn = yn if output is None else output(yn)
            ys.append(yn)
        return torch.stack(ys, dim=1)

    def teacher_forced_norm(self, un: torch.Tensor, yn_meas: torch.Tensor,
                             x0: torch.Tensor | None = None) -> torch.Tensor:
        """Fused: each layer runs over the whole sequence in one ``nn.GRU``/... call."""
        feed = yn_meas[:, :-1]
        inp = torch.cat([self.y_input(feed), un[:, :-1]], dim=2)
        _, hs, cs = self._split(x0) if x0 is not None else (None, [None] * self.config.layers, [])
        for i, layer in enumerate(self.rnn_layers):
            h0 = None if hs[i] is None else (hs[i][None], cs[i][None]) if self.is_lstm else hs[i][None]
            inp, _ = layer(inp, h0)  # None: the zero initial hidden state that init() sets
            inp = self.dropout(inp)
        return self.apply_skip(feed, self.readout(inp))


def _make_layer(config: RecurrentConfig, n_in: int) -> nn.Module:
    common = dict(input_size=n_in, hidden_size=config.hidden, num_layers=1, batch_first=True)
    if config.arch == "lstm":
        return nn.LSTM(**common)
    if config.arch == "gru":
        return nn.GRU(**common)
    return nn.RNN(nonlinearity=config.activation, **common)
