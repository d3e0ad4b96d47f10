"""Initial state from a measured window: what ``init`` does with ``init_window = N > 1``.

A free run starts at ``t0`` from the initial output ``y0`` and input ``u0``. With an init
window, ``init`` also sees the ``N - 1`` samples before them (``y_past``, ``u_past``, oldest
first), so the window is ``[y_{-N+1}, u_{-N+1}] ... [y_0, u_0]`` (newest last). Without them,
the window is the rest state ``(y0, u0)`` repeated: the plant at rest before t0, which is what
``init(y0, u0)`` has always assumed.

What the window becomes, per architecture:

- **RNN, LSTM, GRU**: the hidden (and LSTM cell) state cannot be measured, so a learned
  *encoder* estimates it (SUBNET's encoder): an MLP on the flattened window,
  ``Linear(N (n_y + n_u) -> H_e), tanh, Linear(H_e -> H_e), tanh, Linear(H_e -> layers * hidden
  [* 2])``. Its last layer starts at zero, so a fresh encoder gives the zero state of before.
- **MLP, TCN**: their state is the window of their own last ``L`` samples, all measurable, so
  nothing needs estimating: the measured window fills it (the last ``L`` outputs and the
  ``L - 1`` inputs before ``u0``; a window shorter than ``L`` is padded with its oldest sample).
  The init window thus replaces the assumption of rest by what was measured; a window longer
  than ``L`` adds nothing, and there are no weights to learn.

In increment mode (``ModelConfig.increment``) the encoder sees the outputs relative to ``y0``,
as the network does.
"""

from __future__ import annotations

import torch
from torch import nn

from nnfmu.errors import ShapeError
from nnfmu.models.config import ModelConfig


def make_encoder(config: ModelConfig, n_out: int) -> nn.Sequential:
    """The learned encoder: flattened window ``(N * (n_y + n_u),)`` -> ``n_out`` state entries, last layer zero."""
    n_in, width = config.init_window * config.n_in, config.encoder_hidden
    encoder = nn.Sequential(nn.Linear(n_in, width), nn.Tanh(), nn.Linear(width, width), nn.Tanh(),
                            nn.Linear(width, n_out))
    nn.init.zeros_(encoder[-1].weight)
    nn.init.zeros_(encoder[-1].bias)
    return encoder


def encoder_input(yn_win: torch.Tensor, un_win: torch.Tensor, relative: bool) -> torch.Tensor:
    """Flatten the window ``(B, N, n_y)``, ``(B, N, n_u)`` sample by sample, oldest first -> ``(B, N (n_y + n_u))``.

    ``relative``: outputs relative to the newest one (increment mode).
    """
    if relative:
        yn_win = yn_win - yn_win[:, -1:]
    return torch.cat([yn_win, un_win], dim=2).reshape(yn_win.shape[0], -1)


def last_samples(win: torch.Tensor, n: int, pad: torch.Tensor) -> torch.Tensor:
    """The last ``n`` rows of ``win`` (B, M, C), padded in front with ``pad`` (B, C) when M < n."""
    if win.shape[1] >= n:
        return win[:, win.shape[1] - n:]
    return torch.cat([pad[:, None].expand(-1, n - win.shape[1], -1), win], dim=1)


def window(yn0: torch.Tensor, un0: torch.Tensor, past: tuple | None, n: int) -> tuple[torch.Tensor, torch.Tensor]:
    """The init window ``(B, n, n_y)``, ``(B, n, n_u)``: ``past = (yn_past, un_past)`` then ``(yn0, un0)``.

    Without ``past``, the rest state ``(yn0, un0)`` repeated ``n`` times.
    """
    if past is None:
        return yn0[:, None].expand(-1, n, -1), un0[:, None].expand(-1, n, -1)
    yn_past, un_past = past
    return torch.cat([yn_past, yn0[:, None]], dim=1), torch.cat([un_past, un0[:, None]], dim=1)


def check_past(y_past, u_past, config: ModelConfig, batch: int) -> None:
    """Raise ShapeError unless ``y_past`` (batch, N-1, n_y) and ``u_past`` (batch, N-1, n_u) fit ``config``."""
    n = config.init_window - 1
    if (y_past is None) != (u_past is None):
        raise ShapeError("give both y_past and u_past (the samples before y0 and u0), or neither")
    if n == 0:
        raise ShapeError("this model has init_window 1: it starts from (y0, u0) alone; train it with "
                         "init_window N > 1 to start from a measured window, or drop y_past and u_past")
    for name, a, width in (("y_past", y_past, config.n_y), ("u_past", u_past, config.n_u)):
        if not isinstance(a, torch.Tensor) or tuple(a.shape) != (batch, n, width):
            raise ShapeError(f"{name} has shape {tuple(getattr(a, 'shape', ()))}, expected {(batch, n, width)}: "
                             f"the init_window - 1 = {n} samples before t0, oldest first")
