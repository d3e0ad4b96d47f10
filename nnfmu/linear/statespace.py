"""The discrete-time linear system shared by identification, refinement and the exported model.

``x[k+1] = A x[k] + B u[k] + b``, ``y[k] = C x[k] + d``: there is no ``D``
(direct feedthrough), because nnfmu's contract predicts ``y[k+1]`` from inputs
up to ``u[k]``. The same class is used in normalised coordinates (inside
identification and refinement) and in physical units (inside
:class:`~nnfmu.linear.LinearModel`); the arrays just hold different numbers.

Two rules give the initial state (the ``init`` option):

- ``"estimate"``: ``x0`` reproduces the measured ``y0`` (``C x0 + d = y0`` in least
  squares, rows weighted by ``1 / y_scale``) and, among such states, is the one
  closest to an equilibrium for the input ``u0`` (least squares on
  ``(I - A) x0 = B u0 + b``). Both conditions are linear, so
  ``x0 = K_y (y0 - d) + K_u u0 + k_0`` with constant gains (:func:`init_gains`).
- ``"zero-offset"``: ``x0 = 0`` with inputs and outputs measured from their
  initial values ``u0`` and ``y0`` (the robot benchmark's convention).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

INIT_OPTIONS = ("estimate", "zero-offset")
_RCOND = 1e-10


@dataclass(frozen=True)
class StateSpace:
    """Arrays of one linear system: ``A`` (n, n), ``B`` (n, n_u), ``b`` (n,), ``C`` (n_y, n), ``d`` (n_y,)."""

    A: np.ndarray
    B: np.ndarray
    b: np.ndarray
    C: np.ndarray
    d: np.ndarray

    @property
    def n_x(self) -> int:
        return self.A.shape[0]

    @property
    def spectral_radius(self) -> float:
        return float(np.max(np.abs(np.linalg.eigvals(self.A))))

    def replace(self, **arrays) -> StateSpace:
        return StateSpace(**{**self.__dict__, **arrays})


def init_gains(sys: StateSpace, y_scale: np.ndarray | None = None):
    """Gains of the ``estimate`` rule: ``x0 = K_y @ (y0 - d) + K_u @ u0 + k_0``.

    Parameters
    ----------
    sys : StateSpace
    y_scale : ndarray, shape (n_y,), optional
        Output scales weighting the ``C x0 = y0 - d`` least squares (physical units);
        ones in normalised coordinates.

    Returns
    -------
    K_y : ndarray, shape (n, n_y)
    K_u : ndarray, shape (n, n_u)
    k_0 : ndarray, shape (n,)
    """
    n = sys.n_x
    y_scale = np.ones(sys.C.shape[0]) if y_scale is None else np.asarray(y_scale, dtype=float)
    weighted = sys.C / y_scale[:, None]
    left, sv, right_t = np.linalg.svd(weighted)
    rank = int(np.sum(sv > _RCOND * max(sv[0], 1e-300)))
    c_pinv = right_t[:rank].T @ (left[:, :rank].T / sv[:rank, None])
    null = right_t[rank:].T  # states that C cannot see: choose them to be as stationary as possible
    to_equilibrium = np.eye(n) - sys.A
    if null.shape[1]:
        pick = null @ np.linalg.pinv(to_equilibrium @ null, rcond=_RCOND)
    else:
        pick = np.zeros((n, n))
    K_y = (np.eye(n) - pick @ to_equilibrium) @ c_pinv / y_scale[None, :]
    return K_y, pick @ sys.B, pick @ sys.b


def initial_states(sys: StateSpace, init: str, y0s: np.ndarray, u0s: np.ndarray, y_scale=None) -> np.ndarray:
    """Initial states (batch, n) for initial outputs ``y0s`` (batch, n_y) and inputs ``u0s`` (batch, n_u).

    For ``zero-offset`` the inputs and outputs must already be offset by their
    initial values, so the state starts at zero.
    """
    if init == "zero-offset":
        return np.zeros((len(y0s), sys.n_x))
    K_y, K_u, k_0 = init_gains(sys, y_scale)
    return (y0s - sys.d) @ K_y.T + u0s @ K_u.T + k_0


def free_run(sys: StateSpace, x0s: np.ndarray, us: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Simulate a batch: ``x0s`` (batch, n), ``us`` (batch, N, n_u) -> states and outputs.

    Returns ``xs`` (batch, N, n) with ``xs[:, 0] = x0s`` and ``ys = xs @ C.T + d``
    (batch, N, n_y). ``us[:, N-1]`` is not used. ``xs`` is a view of a time-major array: the
    loop over time then works on contiguous (batch, n) rows (several times faster than strided ones).
    """
    xs = free_run_time_major(sys, x0s, us).transpose(1, 0, 2)
    return xs, xs @ sys.C.T + sys.d


def free_run_time_major(sys: StateSpace, x0s: np.ndarray, us: np.ndarray) -> np.ndarray:
    """States (N, batch, n) of the free run from ``x0s`` (batch, n) under ``us`` (batch, N, n_u)."""
    batch, n_steps, _ = us.shape
    forced = np.ascontiguousarray((us @ sys.B.T + sys.b).transpose(1, 0, 2))  # (N, batch, n)
    xs = np.empty((n_steps, batch, sys.n_x))
    xs[0] = x0s
    A_t = np.ascontiguousarray(sys.A.T)
    for k in range(n_steps - 1):
        np.matmul(xs[k], A_t, out=xs[k + 1])
        xs[k + 1] += forced[k]
    return xs


def padded(arrays, n_steps: int | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Stack 2-D arrays of different lengths into (batch, N, n), zero-padded, and a (batch, N) mask."""
    n_steps = n_steps or max(len(a) for a in arrays)
    out = np.zeros((len(arrays), n_steps, arrays[0].shape[1]))
    mask = np.zeros((len(arrays), n_steps), dtype=bool)
    for i, a in enumerate(arrays):
        out[i, :len(a)] = a
        mask[i, :len(a)] = True
    return out, mask


def stabilise(A: np.ndarray, radius: float) -> np.ndarray:
    """``A`` with every eigenvalue of modulus above ``radius`` pulled radially onto that circle."""
    eig, vec = np.linalg.eig(A)
    if np.max(np.abs(eig)) <= radius:
        return A
    scale = np.minimum(1.0, radius / np.maximum(np.abs(eig), 1e-300))
    return np.real(vec @ np.diag(eig * scale) @ np.linalg.inv(vec))
