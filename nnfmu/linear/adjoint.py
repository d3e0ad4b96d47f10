"""Cost and exact gradient of the free-run output error: one forward pass and one adjoint (reverse) pass.

For ``x[k+1] = A x[k] + B u[k] + b``, ``yhat[k] = C x[k] + d`` and the cost
``J = 1/2 sum_k |r[k]|^2`` with ``r[k] = mask[k] (yhat[k] - y[k])`` (``k = 0`` and padding
masked out), the adjoint ``lam[k] = dJ/dx[k]`` runs backwards::

    lam[N-1] = C^T r[N-1],    lam[k] = A^T lam[k+1] + C^T r[k]
    dJ/dA = sum_k lam[k+1] x[k]^T    dJ/dB = sum_k lam[k+1] u[k]^T    dJ/db = sum_k lam[k+1]
    dJ/dC = sum_k r[k] x[k]^T        dJ/dx[0] = lam[0]

so the whole gradient costs about two free runs, whatever the number of parameters (forward
sensitivities, :meth:`nnfmu.linear.refine._Problem._gram`, cost one run per parameter direction).

The initial state enters by its rule: ``zero-offset`` starts at 0; ``estimate`` solves
``min |(I - A) x0 - (B u0 + b)|`` subject to ``C x0 = y0 - d`` (:func:`init_gains`), whose
derivative follows from the same problem's optimality (KKT) system::

    K [x0; mu] = [(I - A)^T f; e],   K = [[Q, C^T], [C, 0]],   Q = (I - A)^T (I - A),  f = B u0 + b,  e = y0 - d

    with K [xi; eta] = [lam[0]; 0]:   dJ/dA += -f xi^T + (I - A)(x0 xi^T + xi x0^T),
        dJ/dB += (I - A) xi u0^T,   dJ/db += (I - A) xi,   dJ/dC += -mu xi^T - eta x0^T

(summed over trajectories). Fitted initial states (``x0="fit"``) are optimal for every system,
so they add nothing to the gradient (variable projection).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from nnfmu.linear.statespace import StateSpace, free_run_time_major

_RCOND = 1e-10


@dataclass(frozen=True)
class Run:
    """One free run: states (N, batch, n) time-major, masked residuals (N, batch, n_y), its cost and x0."""

    xs: np.ndarray
    resid: np.ndarray
    cost: float


class OutputError:
    """The free-run output error of normalised trajectories; cost and gradient in the full parameters.

    Parameters
    ----------
    u, y : ndarray (batch, N, n_u), (batch, N, n_y)
        Padded trajectories.
    mask : ndarray (batch, N) of bool
        Samples that count (False at ``k = 0`` and in the padding).
    init : {"estimate", "zero-offset"}
        The initial-state rule.
    """

    def __init__(self, u: np.ndarray, y: np.ndarray, mask: np.ndarray, init: str):
        self.u_t = np.ascontiguousarray(u.transpose(1, 0, 2))
        self.y_t = np.ascontiguousarray(y.transpose(1, 0, 2))
        self.mask_t = np.ascontiguousarray(mask.T)[:, :, None].astype(float)
        self.u, self.init = u, init

    def run(self, sys: StateSpace, x0: np.ndarray) -> Run:
        """The free run from ``x0`` (batch, n) and its cost; inf when it overflows."""
        with np.errstate(over="ignore", invalid="ignore"):
            xs = free_run_time_major(sys, x0, self.u)
            resid = (xs @ sys.C.T + sys.d - self.y_t) * self.mask_t
            cost = 0.5 * float(np.sum(resid * resid))
        return Run(xs, resid, cost if np.isfinite(cost) else np.inf)

    def gradient(self, sys: StateSpace, run: Run, rule_x0: bool) -> dict[str, np.ndarray]:
        """``dJ/dA``, ``dJ/dB``, ``dJ/db``, ``dJ/dC`` (``rule_x0``: through the estimate rule's x0 too)."""
        n = sys.n_x
        lam = run.resid @ sys.C  # (N, batch, n): C^T r[k], turned into the adjoint in place
        for k in range(len(lam) - 2, -1, -1):
            lam[k] += lam[k + 1] @ sys.A
        later, states = lam[1:].reshape(-1, n), run.xs[:-1].reshape(-1, n)
        grads = {"A": later.T @ states, "B": later.T @ self.u_t[:-1].reshape(-1, self.u_t.shape[2]),
                 "b": later.sum(axis=0), "C": run.resid.reshape(-1, run.resid.shape[2]).T @ run.xs.reshape(-1, n)}
        if rule_x0 and self.init == "estimate":
            for name, value in estimate_rule_gradient(sys, run.xs[0], self.y_t[0], self.u_t[0], lam[0]).items():
                grads[name] += value
        return grads


def estimate_rule_gradient(sys: StateSpace, x0: np.ndarray, y0: np.ndarray, u0: np.ndarray,
                           lam0: np.ndarray) -> dict[str, np.ndarray]:
    """``d/d(A, B, b, C)`` of ``sum_i lam0_i . x0_i`` for the estimate rule's ``x0_i`` (module docstring).

    ``x0``, ``y0``, ``u0``, ``lam0``: (batch, n), (batch, n_y), (batch, n_u), (batch, n).
    """
    n, n_y = sys.n_x, sys.C.shape[0]
    I_A = np.eye(n) - sys.A
    K = np.block([[I_A.T @ I_A, sys.C.T], [sys.C, np.zeros((n_y, n_y))]])
    f = u0 @ sys.B.T + sys.b  # (batch, n)
    rhs = np.hstack([f @ I_A, y0 - sys.d]).T  # (n + n_y, batch)
    solution = np.linalg.lstsq(K, rhs, rcond=_RCOND)[0]
    mu = solution[n:]  # (n_y, batch); its x0 part equals x0 where the rule's problem is well posed
    adjoint = np.linalg.lstsq(K, np.vstack([lam0.T, np.zeros((n_y, len(lam0)))]), rcond=_RCOND)[0]
    xi, eta = adjoint[:n], adjoint[n:]  # (n, batch), (n_y, batch)
    X = x0.T
    return {"A": -f.T @ xi.T + I_A @ (X @ xi.T + xi @ X.T), "B": I_A @ xi @ u0, "b": I_A @ xi.sum(axis=1),
            "C": -mu @ xi.T - eta @ X.T}


def minimise_output_error(problem, max_evaluations: int):
    """Refine ``problem`` (a :class:`nnfmu.linear.refine._Problem`) by :func:`nnfmu.linear.quasi_newton.minimise`.

    Costs by free runs, gradients by the adjoint pass, the Gauss-Newton matrix from the problem's
    forward sensitivities (at the start, and where BFGS stalls). Every cost evaluation is reported
    to the problem's progress callback. Returns the minimiser's :class:`~nnfmu.linear.quasi_newton.Minimum`.
    """
    from nnfmu.linear.quasi_newton import minimise

    error = OutputError(problem.u, problem.y, problem.mask, problem.init)

    def cost(beta):
        sys = problem.system(beta)
        if not sys.spectral_radius < problem.max_radius:
            problem._count(np.inf)
            return np.inf, None
        run = error.run(sys, problem._fitted_x0(sys) if problem.fit_x0 else problem._rule_x0(sys))
        problem._count(run.cost, sys)
        return run.cost, (sys, run)

    def gradient(beta, state):
        sys, run = state  # fitted initial states are optimal: no term through them (variable projection)
        g = error.gradient(sys, run, rule_x0=not problem.fit_x0)
        full = np.concatenate([g["A"].ravel(), g["B"].ravel(), g["C"].ravel()] + ([g["b"]] if problem.with_b else []))
        return problem.basis.T @ full

    def gauss_newton(beta):
        if problem.cache[0] == beta.tobytes():  # the start: its compressed Jacobian is cached, jac^T jac = J^T J
            return problem.cache[2].T @ problem.cache[2]
        return problem._gram(problem.system(beta), beta)[:-1, :-1]

    return minimise(cost, gradient, gauss_newton, np.zeros(problem.n_dir), max_evaluations=max_evaluations)
