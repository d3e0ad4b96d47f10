"""Subspace identification (N4SID style) from many trajectories of different lengths.

The model identified here lives in normalised coordinates (see
:mod:`nnfmu.linear.identify`)::

    x[k+1] = A x[k] + B u[k] + b        y[k] = C x[k] + d        (no D: y[k] ignores u[k])

Block-Hankel matrices with ``s`` past and ``s`` future block rows are built per
trajectory and their columns stacked side by side, so that no column mixes two
trajectories. One LQ (QR of the transpose) factorisation of the stacked data
gives the oblique projection of future outputs along future inputs onto the
past; its SVD gives the singular values used to choose the order and, for any
order ``n``, a state sequence ``X = Gamma_n^+ O``. ``A, B, b`` and ``C, d`` then
come from least squares on consecutive states of the same trajectory (the
"state-sequence" variant of N4SID), which gives ``D = 0`` directly. For
noise-free data of an order-``n`` system the states are exact, so the model is
recovered up to a change of state basis.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.linalg

from nnfmu.errors import ShapeError

_RCOND = 1e-10  # relative cut-off of the pseudo-inverses: below it a direction is numerically absent


@dataclass(frozen=True)
class SubspaceFit:
    """What the LQ/SVD step leaves behind; realise a model of any order from it.

    Attributes
    ----------
    singular_values : ndarray, shape (s * n_y,)
        Singular values of the oblique projection, largest first.
    horizon : int
        ``s``, the number of past and of future block rows.
    """

    singular_values: np.ndarray
    horizon: int
    left_vectors: np.ndarray  # (s * n_y, s * n_y), left singular vectors of the projection
    past_gain: np.ndarray  # (s * n_y, s * (n_u + n_y)): O = past_gain @ W_p (up to a constant)
    constant: bool

    @property
    def max_order(self) -> int:
        return len(self.singular_values)


def _past(u: np.ndarray, y: np.ndarray, s: int, n_col: int) -> np.ndarray:
    """``W_p`` of one trajectory: rows ``[u_j; ..; u_{j+s-1}; y_j; ..; y_{j+s-1}]``, ``n_col`` columns."""
    rows = [u[i:i + n_col].T for i in range(s)] + [y[i:i + n_col].T for i in range(s)]
    return np.vstack(rows)


def _future(a: np.ndarray, s: int, n_col: int) -> np.ndarray:
    """Future block rows ``[a_{j+s}; ..; a_{j+2s-1}]`` of one trajectory, ``n_col`` columns."""
    return np.vstack([a[s + i:s + i + n_col].T for i in range(s)])


def usable_columns(lengths, s: int) -> int:
    """Number of block-Hankel columns that trajectories of ``lengths`` samples give with horizon ``s``."""
    return int(sum(max(0, int(n) - 2 * s + 1) for n in lengths))


def fit_subspace(us, ys, horizon: int, *, constant: bool = False) -> SubspaceFit:
    """LQ factorisation and SVD of the stacked block-Hankel data.

    Parameters
    ----------
    us, ys : sequences of arrays, shapes (n_steps_i, n_u) and (n_steps_i, n_y)
        Normalised trajectories; those shorter than ``2 * horizon`` samples give no column.
    horizon : int
        ``s`` past and future block rows; orders up to ``s * n_y`` can be realised.
    constant : bool
        Remove the mean of every block row first (the projection on a constant), so that
        constant offsets (``b``, ``d``) are not mistaken for dynamics.
    """
    s = int(horizon)
    n_u, n_y = us[0].shape[1], ys[0].shape[1]
    blocks = []
    for u, y in zip(us, ys):
        n_col = len(u) - 2 * s + 1
        if n_col < 1:
            continue
        blocks.append(np.vstack([_future(u, s, n_col), _past(u, y, s, n_col), _future(y, s, n_col)]))
    n_rows = s * (2 * n_u + 2 * n_y)
    n_cols = sum(b.shape[1] for b in blocks)
    if n_cols < n_rows + int(constant):
        raise ShapeError(
            f"the data give {n_cols} block-Hankel columns with horizon {s}, expected at least "
            f"{n_rows + int(constant)}; use more or longer trajectories, or a smaller order/horizon"
        )
    data = np.hstack(blocks)
    if constant:  # project the constant out of every row, so it is not also seen through the past outputs
        data -= data.mean(axis=1, keepdims=True)
    lower = scipy.linalg.qr(data.T, mode="r", check_finite=False)[0][:n_rows].T  # data = lower @ Q
    n_f = s * n_u
    n_fp = n_f + s * (n_u + n_y)
    regress = lower[:n_fp, :n_fp]
    coef = lower[n_fp:, :n_fp] @ np.linalg.pinv(regress, rcond=_RCOND)  # Y_f ~ coef @ [U_f; 1; W_p]
    past_gain = coef[:, n_f:]
    projection = past_gain @ lower[n_f:n_fp, :n_fp]  # O = projection @ Q[:n_fp], Q orthonormal rows
    left, sv, _ = np.linalg.svd(projection, full_matrices=False)
    return SubspaceFit(sv, s, left, past_gain, constant)


def states(fit: SubspaceFit, order: int, u: np.ndarray, y: np.ndarray) -> np.ndarray:
    """State sequence of one trajectory, shape (n_steps - 2s + 1, order): ``x`` at times ``s, s+1, ...``."""
    s = fit.horizon
    n_col = len(u) - 2 * s + 1
    weights = fit.left_vectors[:, :order] / np.sqrt(fit.singular_values[:order])  # Gamma^+ = S^-1/2 U^T
    return (weights.T @ fit.past_gain @ _past(u, y, s, n_col)).T


def realise(fit: SubspaceFit, order: int, us, ys):
    """Least-squares ``A, B, b, C, d`` of order ``order`` from the state sequences of all trajectories.

    Returns ``(A, B, b, C, d)`` with shapes (n, n), (n, n_u), (n,), (n_y, n), (n_y,);
    ``b`` and ``d`` are zero unless the fit was made with ``constant=True``.
    """
    if not 1 <= order <= fit.max_order:
        raise ShapeError(f"order must be between 1 and {fit.max_order} for horizon {fit.horizon}, got {order}")
    if fit.singular_values[order - 1] <= _RCOND * fit.singular_values[0]:
        raise ShapeError(
            f"order {order} exceeds what the data support: singular value {order} is "
            f"{fit.singular_values[order - 1]:.3g} (largest {fit.singular_values[0]:.3g}); choose a smaller order"
        )
    s, n = fit.horizon, order
    now, nxt, inputs, outputs = [], [], [], []
    for u, y in zip(us, ys):
        if len(u) - 2 * s + 1 < 2:
            continue
        x = states(fit, n, u, y)
        k = np.arange(s, s + len(x))
        now.append(x[:-1])
        nxt.append(x[1:])
        inputs.append(u[k[:-1]])
        outputs.append((x, y[k]))
    x_now, x_next, u_now = np.vstack(now), np.vstack(nxt), np.vstack(inputs)
    ones = [np.ones((len(x_now), 1))] if fit.constant else []
    theta = np.linalg.lstsq(np.hstack([x_now, u_now] + ones), x_next, rcond=None)[0].T
    A, B = theta[:, :n], theta[:, n:n + u_now.shape[1]]
    b = theta[:, -1] if fit.constant else np.zeros(n)
    x_all = np.vstack([x for x, _ in outputs])
    y_all = np.vstack([y for _, y in outputs])
    ones = [np.ones((len(x_all), 1))] if fit.constant else []
    theta = np.linalg.lstsq(np.hstack([x_all] + ones), y_all, rcond=None)[0].T
    C = theta[:, :n]
    d = theta[:, -1] if fit.constant else np.zeros(y_all.shape[1])
    return A, B, b, C, d


def refit_inputs(fit: SubspaceFit, A: np.ndarray, us, ys) -> tuple[np.ndarray, np.ndarray]:
    """Least-squares ``B, b`` for a fixed (for example stabilised) ``A``, from the same state sequences."""
    s, n = fit.horizon, A.shape[0]
    lhs, rhs = [], []
    for u, y in zip(us, ys):
        if len(u) - 2 * s + 1 < 2:
            continue
        x = states(fit, n, u, y)
        u_now = u[s:s + len(x) - 1]
        lhs.append(np.hstack([u_now] + ([np.ones((len(u_now), 1))] if fit.constant else [])))
        rhs.append(x[1:] - x[:-1] @ A.T)
    theta = np.linalg.lstsq(np.vstack(lhs), np.vstack(rhs), rcond=None)[0].T
    n_u = us[0].shape[1]
    return theta[:, :n_u], (theta[:, -1] if fit.constant else np.zeros(n))
