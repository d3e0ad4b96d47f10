"""The TCN's step state: one delay line per dilated layer, so a step computes one new column per layer.

Layer ``i`` (kernel ``k``, dilation ``d = 2**i``) needs its input at
``t, t-d, ..., t-(k-1)d``. Its *delay line* holds the ``(k-1)d`` input columns
before ``t``, oldest first: a ring buffer of the layer's own past input, which a
step rotates by one column (drop the oldest, append the new one). So a step
costs one convolution column per layer, ``O(layers * hidden * k * hidden)``,
instead of recomputing every layer over the whole receptive field. It computes
the same sums as the windowed form in :mod:`nnfmu.networks.tcn.model`, so it predicts
the same outputs. Flat layout, in normalised units (what the FMU carries)::

    x = [ y_k (n_y) | line_0 | line_1 | ... | line_{layers-1} ]
    line_0 = the (k-1) samples [y_j, u_j] before k, oldest first         ((k-1) * (n_y + n_u))
    line_i = the (k-1) 2**i outputs of layer i-1 before k, oldest first  ((k-1) * 2**i * hidden), i >= 1

(the output of layer ``i-1`` is the input of layer ``i``, residual sum included).
``init(y0, u0)`` is the system at rest before ``t0``, as the windowed model pads:
every line holds the column its layer's input has when all past samples are
``[y0, u0]``. :func:`from_window` turns a measured window into this state.
"""

from __future__ import annotations

import torch
from torch.nn import functional as F

from nnfmu.networks.tcn.config import TCNConfig


def line_shapes(config: TCNConfig) -> list[tuple[int, int]]:
    """``(columns, channels)`` of each layer's delay line."""
    k = config.kernel_size
    return [((k - 1) * 2 ** i, config.n_in if i == 0 else config.hidden) for i in range(config.layers)]


def state_size(config: TCNConfig) -> int:
    return config.n_y + sum(n * c for n, c in line_shapes(config))


def split(config: TCNConfig, x: torch.Tensor) -> tuple[torch.Tensor, list[torch.Tensor]]:
    """``x`` (B, n_x) -> ``y_k`` (B, n_y) and the delay lines, each (B, columns, channels)."""
    sizes = [config.n_y] + [n * c for n, c in line_shapes(config)]
    yn, *flat = torch.split(x, sizes, dim=1)
    return yn, [f.reshape(len(x), n, c) for f, (n, c) in zip(flat, line_shapes(config))]


def relative_taps(taps: torch.Tensor, n_y: int) -> torch.Tensor:
    """First-layer taps (..., k, C), oldest first, in increment mode: outputs relative to the newest tap's.

    Each first-layer column sees its own taps' outputs relative to its newest one, so every feature, and
    the step, is the same wherever the output is (translation invariance), and each column is computed
    once from the delay line."""
    return torch.cat([taps[..., :n_y] - taps[..., -1:, :n_y], taps[..., n_y:]], dim=-1)


def column(model, i: int, taps: torch.Tensor) -> torch.Tensor:
    """Layer ``i``'s activation at one position from its ``k`` input columns ``taps`` (B, k, C), oldest first."""
    conv = model.convs[i]
    taps = relative_taps(taps, model.config.n_y) if i == 0 and model.config.increment else taps
    flat = taps.transpose(1, 2).reshape(len(taps), -1)  # channel-major, as the (H, C, k) weight viewed (H, C*k)
    out = model.activation(F.linear(flat, conv.weight.view(conv.out_channels, -1), conv.bias))
    return model.dropout(out) if model.training and model.dropout.p > 0 else out


def step(model, x: torch.Tensor, un: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """One step: ``x`` (B, n_x), ``un`` (B, n_u) -> ``(x_next, yn_next)``, normalised."""
    yn, lines = split(model.config, x)
    h, new_lines = torch.cat([yn, un], dim=1), []
    for i, line in enumerate(lines):
        seq = torch.cat([line, h[:, None]], dim=1)  # the line and the new column: (B, (k-1)d + 1, C)
        out = column(model, i, seq[:, ::2 ** i])
        new_lines.append(seq[:, 1:].reshape(len(x), -1))
        h = out if i == 0 else h + out
    yn_next = model.apply_skip(yn, model.head(h))
    return torch.cat([yn_next, *new_lines], dim=1), yn_next


def from_window(model, samples: torch.Tensor, yn: torch.Tensor) -> torch.Tensor:
    """The state at step k from the ``L - 1`` samples ``[y_j, u_j]`` before k (B, L-1, n_y + n_u), oldest
    first, and ``y_k`` (B, n_y): the windowed layers over the samples give every line."""
    h, lines = samples, []
    for i, (n, _) in enumerate(line_shapes(model.config)):
        lines.append(h[:, h.shape[1] - n:].reshape(len(h), -1))
        if i + 1 < model.config.layers:
            out = model.activation(model._conv(i, h))
            out = model.dropout(out) if model.training and model.dropout.p > 0 else out
            h = out if i == 0 else h[:, h.shape[1] - out.shape[1]:] + out
    return torch.cat([yn, *lines], dim=1)


def init(model, yn0: torch.Tensor, un0: torch.Tensor) -> torch.Tensor:
    """The rest state: ``L - 1`` past samples ``[y0, u0]``."""
    rest = torch.cat([yn0, un0], dim=1)[:, None].expand(-1, model.config.window - 1, -1)
    return from_window(model, rest, yn0)
