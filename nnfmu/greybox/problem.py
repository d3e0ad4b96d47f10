"""The grey-box least-squares problem: simulation error over windows, each with its own initial state.

Every training record is cut into windows of ``L`` samples (the last window of a record ends at its
last sample, so no sample is left out; windows may overlap there). Window ``w`` starts from an unknown
state ``x0_w`` and runs free under the measured inputs::

    x_{k+1} = rk4(x_k, u_k, p),   yhat_k = output(x_k, p),   k = 0 .. L-1,   x_0 = x0_w

The residuals are ``(y_k - yhat_k) / std_y``, every output of every sample of every window, in
normalised units (``std_y``: the training split's standard deviation per output). The unknowns are
``z = [theta / s_theta, vec(X0) / s_x]``: the free parameters and the windows' initial states, each
divided by a typical magnitude (``s_theta``: the nominal value, else the bounds' width, else 1;
``s_x``: the model's ``state_scales``) so that the optimiser sees numbers of order one.

CasADi builds ``r(z)`` (shape ``(n_r,)``) and its exact, sparse Jacobian ``J(z)`` (``(n_r, n_z)``; each
window's residuals depend on theta and its own ``x0_w`` only) from one window Function mapped over the
windows (``mapaccum`` for the RK4 free run, ``map`` over windows), so the graph holds the ODE once.
"""

from __future__ import annotations

from dataclasses import dataclass

import casadi as ca
import numpy as np

from nnfmu.errors import ShapeError
from nnfmu.greybox.window import window_functions
from nnfmu.physics.base import PhysicsSystem
from nnfmu.physics.compiled import compile_function

__all__ = ["Windows", "cut_windows", "Problem", "build_problem", "theta_scales", "DENSE_MAX_WORK"]

#: ``n_r n_z^2`` up to which the Jacobian is dense and trf's trust-region steps exact (an SVD, about a second
#: here); above it a sparse Jacobian and LSMR steps (:attr:`Problem.dense`).
DENSE_MAX_WORK = 1e10


@dataclass(frozen=True)
class Windows:
    """Equal-length pieces of records: ``u`` (n_w, L, n_u), ``y`` (n_w, L, n_y), physical units."""

    u: np.ndarray
    y: np.ndarray

    @property
    def n_w(self) -> int:
        return self.u.shape[0]

    @property
    def length(self) -> int:
        return self.u.shape[1]


def cut_windows(us, ys, length: int) -> Windows:
    """Cut records (lists of ``(n_k, n_u)`` / ``(n_k, n_y)`` arrays) into windows of ``length`` samples.

    Windows start every ``length`` samples; where a record's tail is shorter, one more window ends at its
    last sample. ``length`` must not exceed the shortest record.
    """
    shortest = min(len(u) for u in us)
    if length < 2 or length > shortest:
        raise ShapeError(f"window length {length} must be from 2 to the shortest record's {shortest} samples")
    wu, wy = [], []
    for u, y in zip(us, ys):
        starts = list(range(0, len(u) - length + 1, length))
        if starts[-1] + length < len(u):
            starts.append(len(u) - length)
        wu += [u[s:s + length] for s in starts]
        wy += [y[s:s + length] for s in starts]
    return Windows(np.stack(wu), np.stack(wy))


@dataclass(frozen=True)
class Problem:
    """``r(z)`` and its Jacobian, and how ``z`` maps to the physics.

    Attributes
    ----------
    residuals : casadi.Function
        ``residuals(z) -> r``, shape ``(n_r, 1)`` (a CasADi graph, for IPOPT's own derivatives).
    outputs : casadi.Function
        ``outputs(X0[n_x, n_w], theta[n_f]) -> Y[n_y, n_w L]``: every window's free run.
    derivatives : casadi.Function
        ``derivatives(X0, theta) -> (Y, D[n_y, n_w L (n_x + n_f)])``: also each output's derivative with
        respect to its window's initial state and theta, sample after sample.
    measured : ndarray, shape (n_y, n_w L)
        The measured outputs, window after window.
    free : ndarray of int, shape (n_f,)
        Indices of the free parameters in the model's ``p``.
    p_fixed : ndarray, shape (n_p,)
        The parameter vector with the fixed values (free entries are overwritten by theta).
    theta_scale : ndarray, shape (n_f,)
        ``theta = theta_scale * z[:n_f]``, in the parameters' units.
    x_scale : ndarray, shape (n_x,)
        ``x0_w = x_scale * z[n_f + n_x w : n_f + n_x (w + 1)]``, in the states' units.
    y_std : ndarray, shape (n_y,)
        What each output's residual is divided by.
    """

    residuals: ca.Function
    outputs: ca.Function
    derivatives: ca.Function
    measured: np.ndarray
    free: np.ndarray
    p_fixed: np.ndarray
    theta_scale: np.ndarray
    x_scale: np.ndarray
    y_std: np.ndarray

    @property
    def n_f(self) -> int:
        return len(self.free)

    @property
    def n_x(self) -> int:
        return len(self.x_scale)

    @property
    def n_w(self) -> int:
        return self.outputs.size2_in(0)

    @property
    def n_z(self) -> int:
        return self.n_f + self.n_x * self.n_w

    def parameters(self, z: np.ndarray) -> np.ndarray:
        """The full parameter vector ``p`` (n_p,) at ``z``."""
        p = self.p_fixed.copy()
        p[self.free] = self.theta_scale * np.asarray(z)[:self.n_f]
        return p

    def pack(self, theta: np.ndarray, x0: np.ndarray) -> np.ndarray:
        """``z`` from theta (n_f,) and the windows' initial states ``x0`` (n_w, n_x)."""
        return np.concatenate([np.asarray(theta) / self.theta_scale, (np.asarray(x0) / self.x_scale).ravel()])

    def _unpack(self, z):
        z = np.asarray(z, dtype=float).ravel()
        return (z[self.n_f:].reshape(self.n_w, self.n_x) * self.x_scale).T, self.theta_scale * z[:self.n_f]

    def evaluate(self, z: np.ndarray) -> np.ndarray:
        """``r(z)``, shape ``(n_r,)``: normalised output errors, sample-major (outputs inner), window after window."""
        Y = np.asarray(self.outputs(*self._unpack(z)))
        return ((Y - self.measured) / self.y_std[:, None]).T.ravel()

    def blocks(self, z: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The Jacobian's nonzero blocks: ``dr/dtheta`` (n_w, rows, n_f) and ``dr/dx0_w`` (n_w, rows, n_x).

        ``rows = n_y L`` residuals per window; derivatives with respect to the scaled unknowns ``z``.
        """
        n_w, n_x, n_f, n_y = self.n_w, self.n_x, self.n_f, len(self.y_std)
        D = np.asarray(self.derivatives(*self._unpack(z))[1])
        D = D.reshape(n_y, n_w, -1, n_x + n_f).transpose(1, 2, 0, 3) / self.y_std[:, None]  # (n_w, L, n_y, .)
        D = D.reshape(n_w, -1, n_x + n_f)
        return D[:, :, n_x:] * self.theta_scale, D[:, :, :n_x] * self.x_scale

    @property
    def n_r(self) -> int:
        return self.measured.size

    @property
    def dense(self) -> bool:
        """Whether the Jacobian is small enough to be dense and solved exactly (by SVD): ``n_r n_z^2`` up to
        :data:`DENSE_MAX_WORK`. The arm on 150 windows (17,100 x 1818) is above it: an SVD of it took over a
        minute a step."""
        return self.n_r * self.n_z ** 2 <= DENSE_MAX_WORK

    def jacobian(self, z: np.ndarray):
        """``J(z)``, shape ``(n_r, n_z)``: dense where :attr:`dense`, else a scipy CSR matrix.

        Each window's rows depend on theta and its own initial state only (an arrow-shaped pattern).
        """
        import scipy.sparse as sp

        dt, dx = self.blocks(z)
        n_w, rows = dx.shape[:2]
        dt = dt.reshape(n_w * rows, self.n_f)
        if not self.dense:
            return sp.hstack([sp.csr_matrix(dt), sp.block_diag(list(dx), format="csr")], format="csr")
        J = np.zeros((n_w * rows, self.n_z))
        J[:, :self.n_f] = dt
        for w in range(n_w):
            J[w * rows:(w + 1) * rows, self.n_f + w * self.n_x:self.n_f + (w + 1) * self.n_x] = dx[w]
        return J


def theta_scales(start: np.ndarray, lower: np.ndarray, upper: np.ndarray) -> np.ndarray:
    """A typical magnitude per free parameter: ``|start|``, else the bounds' width, else 1."""
    width = np.where(np.isfinite(upper - lower), upper - lower, 0.0)
    return np.where(start != 0, np.abs(start), np.where(width > 0, width, 1.0))


def build_problem(system: PhysicsSystem, windows: Windows, free: np.ndarray, p_fixed: np.ndarray,
                  theta_scale: np.ndarray, y_std: np.ndarray, *, n_sub: int, compile: bool = False) -> Problem:
    """The :class:`Problem` of ``system`` on ``windows`` (free parameter indices ``free``; module docstring).

    ``compile``: the window Functions behind ``outputs`` and ``derivatives`` run as compiled C (same values;
    without a working C compiler they stay in CasADi's virtual machine, with a warning). ``residuals``, which
    IPOPT differentiates, stays a CasADi graph.
    """
    n_x, n_w, L = system.n_x, windows.n_w, windows.length
    x_scale = np.asarray(system.state_scales or (1.0,) * n_x, dtype=float)
    free, n_f = np.asarray(free, dtype=int), len(free)
    select = np.zeros((len(p_fixed), n_f))
    select[free, np.arange(n_f)] = 1.0
    base = np.asarray(p_fixed, dtype=float).copy()
    base[free] = 0.0
    U = ca.DM(np.concatenate([w[:-1].T for w in windows.u], axis=1))  # (n_u, n_w (L-1)), window after window
    window, window_derivatives = window_functions(system, L, n_sub, base, select)
    over_windows = lambda f: f.map("windows", "serial", n_w, [2], [])  # noqa: E731
    plain = over_windows(window)
    run = over_windows(compile_function(window)) if compile else plain
    derivatives = over_windows(compile_function(window_derivatives) if compile else window_derivatives)
    X0, theta = ca.MX.sym("X0", n_x, n_w), ca.MX.sym("theta", n_f)
    outputs = ca.Function("outputs", [X0, theta], [run(X0, U, theta)], ["X0", "theta"], ["Y"])
    derivatives = ca.Function("derivatives", [X0, theta], derivatives(X0, U, theta), ["X0", "theta"], ["Y", "D"])
    measured = np.concatenate([w.T for w in windows.y], axis=1)
    y_std = np.asarray(y_std, dtype=float)
    z = ca.MX.sym("z", n_f + n_x * n_w)
    Y = plain(ca.reshape(z[n_f:], n_x, n_w) * ca.repmat(ca.DM(x_scale), 1, n_w), U, ca.DM(theta_scale) * z[:n_f])
    r = ca.vec((Y - ca.DM(measured)) / ca.repmat(ca.DM(y_std), 1, n_w * L))
    return Problem(residuals=ca.Function("residuals", [z], [r], ["z"], ["r"]), outputs=outputs, derivatives=derivatives,
                   measured=measured, free=free, p_fixed=np.asarray(p_fixed, dtype=float),
                   theta_scale=np.asarray(theta_scale, dtype=float), x_scale=x_scale, y_std=y_std)
