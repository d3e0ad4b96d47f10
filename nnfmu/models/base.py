"""``StepModel``: the one step interface every network implements (docs/design.md, "The one idea").

Every network is a discrete-time step in physical units::

    x0            = model.init(y0, u0)        # y0 (B, n_y), u0 (B, n_u) -> x0 (B, n_x)
    x1, y1        = model.step(x0, u0)        # y1 = y(t0 + Ts); no feedthrough from u0 to y0
    x2, y2        = model.step(x1, u1)        # ... the caller's free-run loop

``model(u, y0)`` runs that loop over a sequence (free run), and
``model(u, y0, y_meas)`` feeds the measured outputs instead of the predictions
(teacher forcing, series-parallel training). ``model.simulate(u, y0)`` is the
numpy free run in float64 that scores and FMUs are compared with.

Internally the network works in normalised units, ``(v - mean) / std`` with
the mean and std of the training split held as buffers (``u_mean``,
``u_std``, ``y_mean``, ``y_std``), so they are saved, moved and exported with
the weights. The flat state ``x`` is kept in normalised units too; its layout
is documented by each architecture and reproduced exactly by
:func:`nnfmu.export.to_casadi`.
"""

from __future__ import annotations

import contextlib
import copy
from typing import Mapping

import numpy as np
import torch
from torch import nn

from nnfmu.errors import DataError, ShapeError
from nnfmu.models.config import ModelConfig
from nnfmu.models.encoder import check_past, window


def default_meta(config: ModelConfig) -> dict:
    """Meta of a model made without a dataset: ``u1..``, ``y1..`` without units, Ts = 1 s."""
    return {
        "name": f"{config.arch}_model",
        "Ts": 1.0,
        "inputs": [{"name": f"u{j + 1}", "unit": ""} for j in range(config.n_u)],
        "outputs": [{"name": f"y{j + 1}", "unit": ""} for j in range(config.n_y)],
    }


def check_meta(meta: Mapping, config: ModelConfig) -> dict:
    """Return a plain-dict copy of ``meta`` after checking its channels against ``config``."""
    meta = copy.deepcopy(dict(meta))
    for key, n in (("inputs", config.n_u), ("outputs", config.n_y)):
        chans = meta.get(key)
        if not isinstance(chans, list) or len(chans) != n:
            got = len(chans) if isinstance(chans, list) else chans
            raise ShapeError(f"meta[{key!r}] must list {n} channels {{name, unit}} to match the config, got {got}")
    ts = meta.get("Ts")
    if not isinstance(ts, (int, float)) or not ts > 0:
        raise ShapeError(f"meta['Ts'] must be the positive sample time in seconds, got {ts!r}")
    return meta


class StepModel(nn.Module):
    """Public base of every architecture's model; see the module docstring for the step contract.

    Subclasses implement the normalised core, public hooks all (docs/design.md, "Adding an architecture"):
    :attr:`n_x`, :meth:`init_norm`, :meth:`step_norm`, :meth:`inject_y` (used by the generic teacher-forced
    loop), and may override :meth:`init_window_norm`, :meth:`teacher_forced_norm` and
    :meth:`free_run_norm` with faster equivalent calls. They call
    :meth:`check_sizes` at the end of ``__init__``; :meth:`apply_skip` and :meth:`y_input` give the skip
    connection and increment mode.

    Attributes
    ----------
    config : ModelConfig
        Frozen architecture and sizes.
    meta : dict
        ``Ts`` (s), ``inputs`` and ``outputs`` as lists of ``{name, unit}``, copied from the dataset.
    provenance : dict
        Where the weights come from (checkpoint path, training figures); empty for a fresh model.
    """

    #: Whether its free runs feed back an output that training may disturb (``TrainConfig.feedback_noise``).
    takes_feedback_noise = True

    def __init__(self, config: ModelConfig, meta: Mapping | None = None):
        super().__init__()
        if not isinstance(config, ModelConfig):
            raise ShapeError(f"expected a ModelConfig, got {type(config).__name__}; "
                             "build one with ModelConfig(arch=...)")
        self.config = config
        self.meta = default_meta(config) if meta is None else check_meta(meta, config)
        self.provenance: dict = {}
        self.register_buffer("u_mean", torch.zeros(config.n_u))
        self.register_buffer("u_std", torch.ones(config.n_u))
        self.register_buffer("y_mean", torch.zeros(config.n_y))
        self.register_buffer("y_std", torch.ones(config.n_y))
        if getattr(config, "increment", False):  # per-output increment scale, normalised units (set from data)
            self.register_buffer("increment_scale", torch.full((config.n_y,), float(config.skip_scale)))
        self.feedback_noise = 0.0  # std of the noise on the fed-back output in training free runs (normalised)

    # ---- what subclasses provide -------------------------------------------------------------
    @property
    def n_x(self) -> int:
        """Size of the flat state vector."""
        raise NotImplementedError

    def init_norm(self, yn0: torch.Tensor, un0: torch.Tensor) -> torch.Tensor:
        """Initial state ``x0`` (B, n_x) from ``yn0`` (B, n_y) and ``un0`` (B, n_u), normalised: the plant at rest."""
        raise NotImplementedError

    def step_norm(self, x: torch.Tensor, un: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """One step, normalised: ``x`` (B, n_x), ``un`` (B, n_u) -> ``(x_next (B, n_x), yn_next (B, n_y))``."""
        raise NotImplementedError

    def inject_y(self, x: torch.Tensor, yn: torch.Tensor) -> torch.Tensor:
        """State ``x`` (B, n_x) with its newest output ``y_k`` replaced by ``yn`` (B, n_y) (teacher forcing)."""
        raise NotImplementedError

    def init_window_norm(self, yn_win: torch.Tensor, un_win: torch.Tensor) -> torch.Tensor:
        """Initial state from the init window (B, N, n_y), (B, N, n_u), newest sample last.

        Architectures with ``init_window > 1`` override it (:mod:`nnfmu.models.encoder`).
        """
        return self.init_norm(yn_win[:, -1], un_win[:, -1])

    def apply_skip(self, yn: torch.Tensor, n: torch.Tensor) -> torch.Tensor:
        """Apply the optional skip connection to ``yn`` and the network's output ``n`` (both (B, n_y), normalised):
        ``y_{k+1} = y_k + scale * N`` or ``N``.

        ``scale`` is ``skip_scale``, or in increment mode the per-output ``increment_scale``.
        """
        if not self.config.skip:
            return n
        return yn + (self.increment_scale if self.config.increment else self.config.skip_scale) * n

    def y_input(self, yn: torch.Tensor) -> torch.Tensor:
        """What a one-sample network sees of its newest output: ``yn``, or in increment mode ``yn`` relative to
        itself (zeros): the response must not depend on where the output is."""
        return torch.zeros_like(yn) if self.config.increment else yn

    def _feedback(self, yn: torch.Tensor) -> torch.Tensor:
        """The output fed back in a free run: ``yn``, plus white noise of std :attr:`feedback_noise` in training."""
        if self.feedback_noise and self.training:
            return yn + self.feedback_noise * torch.randn_like(yn)
        return yn

    @staticmethod
    def _unshifted(yn_next: torch.Tensor, fed: torch.Tensor, yn: torch.Tensor) -> torch.Tensor:
        """Increment mode with feedback noise: the step's output less the noise it started from.

        An increment ``y_{k+1} = y_fed + s N`` starting from the disturbed ``y_fed = y_k + noise`` would carry the
        noise into every later output, a random walk (issue 21: training losses of 12-600 on an integrating
        axis). The network still *sees* the disturbed output; the increment is added to the undisturbed one.
        """
        return yn_next - (fed - yn)

    def check_sizes(self) -> None:
        """Dry-run init and step at batch 2 so that inconsistent sizes fail at construction."""
        c = self.config
        try:
            with torch.no_grad():
                dtype = self.u_mean.dtype
                x0 = self.init_norm(torch.zeros(2, c.n_y, dtype=dtype), torch.zeros(2, c.n_u, dtype=dtype))
                x1, y1 = self.step_norm(x0, torch.zeros(2, c.n_u, dtype=dtype))
        except RuntimeError as exc:
            raise ShapeError(f"{type(self).__name__} with {c} has inconsistent layer sizes: {exc}") from exc
        for what, got, want in (("init -> x0", x0.shape, (2, self.n_x)), ("step -> x_next", x1.shape, (2, self.n_x)),
                                ("step -> y_next", y1.shape, (2, c.n_y))):
            if tuple(got) != want:
                raise ShapeError(f"{type(self).__name__}: {what} has shape {tuple(got)}, expected {want}; "
                                 "the sub-networks do not fit the config")

    def set_increment_scale(self, dy_std) -> None:
        """Set the increment-mode scale from the std of the one-step output increments, ``(n_y,)`` physical units."""
        if not self.config.increment:
            raise ShapeError("set_increment_scale needs a model built with increment=True")
        value = torch.as_tensor(np.asarray(dy_std, dtype=np.float64)).reshape(-1).to(self.y_std.dtype) / self.y_std
        if value.shape != (self.config.n_y,) or not (torch.isfinite(value).all() and (value > 0).all()):
            raise DataError(f"increment std must be {self.config.n_y} positive finite values, got {value.tolist()}; "
                            "the training outputs must change from sample to sample")
        self.increment_scale.copy_(value)

    # ---- normalisation -----------------------------------------------------------------------
    def set_normalisation(self, stats) -> None:
        """Set the buffers from :class:`nnfmu.data.NormStats` (or a mapping with the same four arrays).

        Means and standard deviations are in physical units, shapes ``(n_u,)`` and ``(n_y,)``.
        """
        get = stats.get if isinstance(stats, Mapping) else (lambda k: getattr(stats, k))
        for name, n in (("u_mean", self.config.n_u), ("u_std", self.config.n_u),
                        ("y_mean", self.config.n_y), ("y_std", self.config.n_y)):
            value = torch.as_tensor(np.asarray(get(name), dtype=np.float64)).reshape(-1)
            if value.shape != (n,):
                raise ShapeError(f"normalisation {name} has shape {tuple(value.shape)}, expected ({n},)")
            if not torch.isfinite(value).all() or (name.endswith("std") and (value <= 0).any()):
                raise DataError(f"normalisation {name} must be finite (std > 0), got {value.tolist()}")
            getattr(self, name).copy_(value)

    def normalise_u(self, u: torch.Tensor) -> torch.Tensor:
        return (u - self.u_mean) / self.u_std

    def normalise_y(self, y: torch.Tensor) -> torch.Tensor:
        return (y - self.y_mean) / self.y_std

    def denormalise_y(self, yn: torch.Tensor) -> torch.Tensor:
        return yn * self.y_std + self.y_mean

    # ---- the public step interface (physical units) ------------------------------------------
    def init(self, y0: torch.Tensor, u0: torch.Tensor, y_past: torch.Tensor | None = None,
             u_past: torch.Tensor | None = None) -> torch.Tensor:
        """Initial state ``x0`` (B, n_x) from the initial output ``y0`` (B, n_y) and input ``u0`` (B, n_u).

        With ``config.init_window = N > 1``, also from the ``N - 1`` samples before them, ``y_past``
        (B, N-1, n_y) and ``u_past`` (B, N-1, n_u), oldest first; without them the plant is taken at
        rest, ``(y0, u0)`` repeated (:mod:`nnfmu.models.encoder`).
        """
        self._check_batch(y0, self.config.n_y, "y0")
        self._check_batch(u0, self.config.n_u, "u0", len(y0))
        return self.init_window_norm(*self._window(self.normalise_y(y0), self.normalise_u(u0),
                                                    self._past(y_past, u_past, len(y0))))

    def _past(self, y_past, u_past, batch: int) -> tuple | None:
        """``(yn_past, un_past)`` normalised, or None; checked against the config."""
        if y_past is None and u_past is None:
            return None
        check_past(y_past, u_past, self.config, batch)
        return self.normalise_y(y_past), self.normalise_u(u_past)

    def _window(self, yn0: torch.Tensor, un0: torch.Tensor, past: tuple | None) -> tuple[torch.Tensor, torch.Tensor]:
        return window(yn0, un0, past, self.config.init_window)

    def step(self, x: torch.Tensor, u: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """One sample period: state ``x`` (B, n_x) and input ``u`` (B, n_u) -> ``(x_next, y_next)``.

        ``y_next`` (B, n_y) is the output at ``t + Ts`` in physical units.
        """
        self._check_batch(x, self.n_x, "x")
        self._check_batch(u, self.config.n_u, "u", len(x))
        x_next, yn_next = self.step_norm(x, self.normalise_u(u))
        return x_next, self.denormalise_y(yn_next)

    def _check_batch(self, a, n: int, name: str, batch: int | None = None) -> None:
        ok = isinstance(a, torch.Tensor) and a.ndim == 2 and a.shape[1] == n
        if not ok or (batch is not None and len(a) != batch):
            shape = tuple(a.shape) if hasattr(a, "shape") else type(a).__name__
            want = f"({'B' if batch is None else batch}, {n})"
            raise ShapeError(f"{name} has shape {shape}, expected a tensor of shape {want}")

    # ---- sequences ---------------------------------------------------------------------------
    def free_run_norm(self, un: torch.Tensor, yn0: torch.Tensor, x0: torch.Tensor | None = None,
                       output=None) -> torch.Tensor:
        """Free run in normalised units: (B, T, n_u), (B, n_y) -> (B, T, n_y), first row ``yn0``.

        ``x0``: the initial state (default ``init_norm(yn0, un[:, 0])``). ``output``: called once per step, in
        order, on the step's output (B, n_y); what it returns is the output, fed back (a linear path's sum).
        """
        x = self.init_norm(yn0, un[:, 0]) if x0 is None else x0
        ys = [yn0]
        noisy = bool(self.feedback_noise and self.training)
        for k in range(un.shape[1] - 1):
            fed = self._feedback(ys[-1]) if noisy else None
            x, yn = self.step_norm(x if fed is None else self.inject_y(x, fed), un[:, k])
            if fed is not None and self.config.increment:
                yn = self._unshifted(yn, fed, ys[-1])
                x = self.inject_y(x, yn)
            if output is not None:
                yn = output(yn)
                x = self.inject_y(x, yn)
            ys.append(yn)
        return torch.stack(ys, dim=1)

    def teacher_forced_norm(self, un: torch.Tensor, yn_meas: torch.Tensor,
                             x0: torch.Tensor | None = None) -> torch.Tensor:
        """One-step-ahead predictions of ``yn_meas[:, 1:]`` from ``yn_meas[:, k]``, ``un[:, k]``: (B, T-1, n_y).

        The generic loop over :meth:`step_norm`; subclasses override it with fused calls.
        """
        x = self.init_norm(yn_meas[:, 0], un[:, 0]) if x0 is None else x0
        preds = []
        for k in range(un.shape[1] - 1):
            x = self.inject_y(x, yn_meas[:, k])
            x, yn = self.step_norm(x, un[:, k])
            preds.append(yn)
        return torch.stack(preds, dim=1)

    def rollout_normalised(self, un: torch.Tensor, yn0: torch.Tensor, yn_meas: torch.Tensor | None = None,
                           past: tuple | None = None) -> torch.Tensor:
        """:meth:`forward` in normalised units (what the trainer's loss sees): (B, T, n_y).

        ``past``: ``(yn_past, un_past)``, the normalised samples before t0 (init window).
        """
        x0 = ()
        if past is not None or self.config.init_window > 1:
            x0 = (self.init_window_norm(*self._window(yn0, un[:, 0], past)),)
        if yn_meas is None:
            return self.free_run_norm(un, yn0, *x0)
        return torch.cat([yn0[:, None], self.teacher_forced_norm(un, yn_meas, *x0)], dim=1)

    def forward(self, u: torch.Tensor, y0: torch.Tensor, y_meas: torch.Tensor | None = None, *,
                y_past: torch.Tensor | None = None, u_past: torch.Tensor | None = None) -> torch.Tensor:
        """Sequence call in physical units.

        Parameters
        ----------
        u : tensor (B, T, n_u)
            Inputs; ``u[:, T-1]`` is not used.
        y0 : tensor (B, n_y)
            Initial outputs; the first row of the result.
        y_meas : tensor (B, T, n_y), optional
            Measured outputs. If given, ``y_meas[:, k]`` is fed as ``y_k`` (teacher forcing);
            otherwise the model's own predictions are fed back (free run).
        y_past, u_past : tensor (B, N-1, n_y), (B, N-1, n_u), optional
            The samples before t0 for a model with ``init_window = N > 1`` (see :meth:`init`).

        Returns
        -------
        tensor (B, T, n_y)
        """
        c = self.config
        if not isinstance(u, torch.Tensor) or u.ndim != 3 or u.shape[2] != c.n_u or u.shape[1] < 1:
            raise ShapeError(f"u has shape {tuple(getattr(u, 'shape', ()))}, expected (B, T, {c.n_u}) with T >= 1")
        self._check_batch(y0, c.n_y, "y0", u.shape[0])
        want = (*u.shape[:2], c.n_y)
        if y_meas is not None and (not isinstance(y_meas, torch.Tensor) or tuple(y_meas.shape) != want):
            raise ShapeError(f"y_meas has shape {tuple(getattr(y_meas, 'shape', ()))}, "
                             f"expected {(*u.shape[:2], c.n_y)} to match u")
        ynm = None if y_meas is None else self.normalise_y(y_meas)
        past = self._past(y_past, u_past, u.shape[0])
        yn = self.rollout_normalised(self.normalise_u(u), self.normalise_y(y0), ynm, past)
        return torch.cat([y0[:, None], self.denormalise_y(yn[:, 1:])], dim=1)

    def simulate(self, u, y0, *, y_past=None, u_past=None) -> np.ndarray:
        """Free run in float64 on numpy arrays in physical units.

        Parameters
        ----------
        u : array (N, n_u)
            Inputs; ``u[N-1]`` is not used.
        y0 : array (n_y,)
            Initial output, returned as the first row.
        y_past, u_past : array (init_window - 1, n_y), (init_window - 1, n_u), optional
            The measured samples before ``y0`` and ``u[0]``, oldest first (default: at rest).

        Returns
        -------
        ndarray (N, n_y)
        """
        c = self.config
        u = np.array(u, dtype=np.float64)  # a private, writable copy for torch.from_numpy
        y0 = np.array(y0, dtype=np.float64)
        if u.ndim != 2 or u.shape[1] != c.n_u or len(u) < 1:
            raise ShapeError(f"u has shape {u.shape}, expected (n_steps, {c.n_u}) with n_steps >= 1")
        if y0.shape != (c.n_y,):
            raise ShapeError(f"y0 has shape {y0.shape}, expected ({c.n_y},)")
        if not (np.isfinite(u).all() and np.isfinite(y0).all()):
            raise DataError("u or y0 has non-finite values; remove or interpolate them before simulating")
        past = {}
        if y_past is not None or u_past is not None:
            past = {k: None if v is None else torch.from_numpy(np.array(v, dtype=np.float64))[None]
                    for k, v in (("y_past", y_past), ("u_past", u_past))}
        model = copy.deepcopy(self).double().eval()
        with torch.no_grad(), torch_threads(1):
            y = model(torch.from_numpy(u)[None], torch.from_numpy(y0)[None], **past)[0]
        return y.numpy()


@contextlib.contextmanager
def torch_threads(n: int = 1):
    """Run torch on ``n`` intra-op threads inside the block, then restore the previous count.

    Small networks step through thousands of tiny operations; splitting each over
    threads only adds synchronisation, which on a busy machine made a batch-1 TCN
    free run 80x slower (15.8 s against 0.19 s for 500 steps). So one is the default.
    """
    before = torch.get_num_threads()
    torch.set_num_threads(n)
    try:
        yield
    finally:
        torch.set_num_threads(before)
