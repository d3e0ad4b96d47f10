"""Window models (MLP, TCN): the network sees the last ``L`` samples of ``[y, u]``.

The MLP's flat state, in normalised units (what the FMU carries), is that window
(the TCN keeps delay lines instead: :mod:`nnfmu.networks.tcn.state`)::

    x = [ y_{k-L+1} | ... | y_k   (L * n_y) | u_{k-L+1} | ... | u_{k-1}   ((L-1) * n_u) ]

oldest sample first. ``step(x, u_k)`` appends ``u_k`` to complete the window
of ``L`` samples ``[y_j, u_j]``, predicts ``y_{k+1}``, and shifts the window
by one sample. ``init(y0, u0)`` fills the window with ``y0`` and ``u0``: the
system at rest before ``t0``; with an init window (``init_window > 1``) the
measured samples before t0 fill it instead (:mod:`nnfmu.models.encoder`).
Teacher forcing pads the measured sequence on the left the same way and
evaluates all windows in one fused call. In increment mode the MLP sees the
window's outputs relative to its newest one, ``y_j - y_k`` (the TCN: each
first-layer column relative to its own newest tap, :mod:`nnfmu.networks.tcn.state`).
"""

from __future__ import annotations

import torch

from nnfmu.errors import ShapeError
from nnfmu.models.base import StepModel
from nnfmu.models.encoder import last_samples


class WindowStepModel(StepModel):
    """Base of the MLP and TCN; subclasses map windows of samples to the network output ``N``.

    They implement :meth:`_predict_windows` (one window per batch row, used by
    the step) and :meth:`_predict_sequence` (all windows of a padded sequence
    at once, used by teacher forcing).
    """

    # In increment mode the network sees the whole window relative to its newest output (the MLP); False:
    # the subclass makes its features translation invariant itself (the TCN, per first-layer column).
    relative_window = True

    @property
    def n_x(self) -> int:
        c = self.config
        return c.window * c.n_y + (c.window - 1) * c.n_u

    def _predict_windows(self, window: torch.Tensor) -> torch.Tensor:
        """``window`` (B, L, n_y + n_u), oldest first -> ``N`` (B, n_y)."""
        raise NotImplementedError

    def _predict_sequence(self, padded: torch.Tensor) -> torch.Tensor:
        """``padded`` (B, T + L - 1, n_y + n_u) -> ``N`` of each of its T windows (B, T, n_y)."""
        raise NotImplementedError

    def init_norm(self, yn0: torch.Tensor, un0: torch.Tensor) -> torch.Tensor:
        L = self.config.window
        return torch.cat([yn0.repeat(1, L), un0.repeat(1, L - 1)], dim=1)

    def init_window_norm(self, yn_win: torch.Tensor, un_win: torch.Tensor) -> torch.Tensor:
        """The measured window gives the state: its last ``L`` outputs and the ``L - 1`` inputs before ``u0``
        (padded in front with the window's oldest sample when it is shorter than ``L``)."""
        L = self.config.window
        return self.state_from_window(last_samples(yn_win, L, yn_win[:, 0]),
                                      last_samples(un_win[:, :-1], L - 1, un_win[:, 0]))

    def _relative(self, window: torch.Tensor) -> torch.Tensor:
        """The window (B, L, n_y + n_u) as the network sees it: in increment mode, outputs minus the newest."""
        if not (self.config.increment and self.relative_window):
            return window
        n_y = self.config.n_y
        return torch.cat([window[..., :n_y] - window[..., -1:, :n_y], window[..., n_y:]], dim=-1)

    def _samples(self, x: torch.Tensor) -> torch.Tensor:
        """The ``L - 1`` older samples ``[y_j, u_j]`` of a flat state: (B, L-1, n_y + n_u)."""
        c, B = self.config, x.shape[0]
        split = c.window * c.n_y
        y_old = x[:, :split - c.n_y].reshape(B, c.window - 1, c.n_y)
        return torch.cat([y_old, x[:, split:].reshape(B, c.window - 1, c.n_u)], dim=2)

    def step_norm(self, x: torch.Tensor, un: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        c, B = self.config, x.shape[0]
        split = c.window * c.n_y
        y_win = x[:, :split].reshape(B, c.window, c.n_y)
        u_win = torch.cat([x[:, split:].reshape(B, c.window - 1, c.n_u), un[:, None]], dim=1)
        yn_k = y_win[:, -1]
        yn_next = self.apply_skip(yn_k, self._predict_windows(self._relative(torch.cat([y_win, u_win], dim=2))))
        x_next = torch.cat([y_win[:, 1:].reshape(B, -1), yn_next, u_win[:, 1:].reshape(B, -1)], dim=1)
        return x_next, yn_next

    def free_run_norm(self, un: torch.Tensor, yn0: torch.Tensor, x0: torch.Tensor | None = None,
                       output=None) -> torch.Tensor:
        """Free run on a window tensor instead of the flat state: 2 concatenations per step instead of 6.

        The network sees the same numbers in the same layout as in :meth:`step_norm`, so the
        result is identical. ``output`` as in :meth:`StepModel.free_run_norm`.
        """
        if x0 is None:  # the rest state
            samples = torch.cat([yn0, un[:, 0]], dim=1)[:, None].expand(-1, self.config.window - 1, -1)
        else:
            samples = self._samples(x0)
        yn, ys = yn0, [yn0]
        noisy_increments = bool(self.feedback_noise and self.training and self.config.increment)
        for un_k in un[:, :-1].unbind(1):
            fed = self._feedback(yn)
            window = torch.cat([samples, torch.cat([fed, un_k], dim=1)[:, None]], dim=1)
            y_next = self.apply_skip(fed, self._predict_windows(self._relative(window)))
            yn = self._unshifted(y_next, fed, yn) if noisy_increments else y_next
            yn = yn if output is None else output(yn)
            ys.append(yn)
            samples = window[:, 1:]
        return torch.stack(ys, dim=1)

    def state_from_window(self, yn_window: torch.Tensor, un_window: torch.Tensor) -> torch.Tensor:
        """The state at step k from a measured window, normalised: ``y_{k-L+1..k}`` (B, L, n_y) and
        ``u_{k-L+1..k-1}`` (B, L-1, n_u), oldest first -> ``x`` (B, n_x)."""
        self._check_window(yn_window, un_window)
        return torch.cat([yn_window.flatten(1), un_window.flatten(1)], dim=1)

    def _check_window(self, yn_window: torch.Tensor, un_window: torch.Tensor) -> None:
        c = self.config
        if tuple(yn_window.shape[1:]) != (c.window, c.n_y) or tuple(un_window.shape[1:]) != (c.window - 1, c.n_u):
            raise ShapeError(f"the window has shapes {tuple(yn_window.shape)} and {tuple(un_window.shape)}, expected "
                             f"(B, {c.window}, {c.n_y}) and (B, {c.window - 1}, {c.n_u})")

    def inject_y(self, x: torch.Tensor, yn: torch.Tensor) -> torch.Tensor:
        split = self.config.window * self.config.n_y
        return torch.cat([x[:, :split - self.config.n_y], yn, x[:, split:]], dim=1)

    def teacher_forced_norm(self, un: torch.Tensor, yn_meas: torch.Tensor,
                             x0: torch.Tensor | None = None) -> torch.Tensor:
        """Fused: every window of the measured sequence in one call of the network.

        In increment mode each window is made relative to its own newest output, so the windows are
        cut out (unfold) and the network sees them one by one, as in :meth:`step_norm`.
        """
        feed = yn_meas[:, :-1]
        seq = torch.cat([feed, un[:, :-1]], dim=2)
        older = seq[:, :1].expand(-1, self.config.window - 1, -1) if x0 is None else self._samples(x0)
        padded = torch.cat([older, seq], dim=1)
        if not (self.config.increment and self.relative_window):
            return self.apply_skip(feed, self._predict_sequence(padded))
        windows = padded.unfold(1, self.config.window, 1).transpose(2, 3)  # (B, T-1, L, C)
        flat = self._relative(windows.reshape(-1, *windows.shape[2:]))
        return self.apply_skip(feed, self._predict_windows(flat).reshape(*feed.shape))
