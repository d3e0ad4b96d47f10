"""A damped quasi-Newton minimiser for the output-error refinement: Gauss-Newton start, BFGS updates.

Each iteration solves ``(H + lam diag(H)) p = -g`` (Levenberg-Marquardt damping with
Marquardt's scaling), evaluates the cost at ``beta + p`` (one free run) and, if the step is
accepted, the exact gradient there (one adjoint pass, :mod:`nnfmu.linear.adjoint`), then
updates ``H`` by the damped BFGS formula (Powell), which keeps it positive definite. ``H``
starts as the Gauss-Newton matrix ``J^T J`` (forward sensitivities, one expensive pass), so
the first steps are Gauss-Newton steps; afterwards no Jacobian is formed. ``lam`` follows
Nielsen's rule from the ratio of actual to predicted decrease. A step whose system is unstable
costs ``inf`` and is rejected like any step that does not decrease the cost.

Compared with a Gauss-Newton method that forms ``J^T J`` at every iteration (scipy's trust-region
reflective on the compressed problem, used before): an evaluation costs two free runs instead of
one run per parameter direction (156 on the robot at 12 states), so about a hundred times less,
and it takes more, cheaper iterations (figures in docs/scaling.md).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np
import scipy.linalg


@dataclass(frozen=True)
class Minimum:
    """Where the minimiser stopped: coordinates, cost, cost evaluations and why it stopped."""

    x: np.ndarray
    cost: float
    evaluations: int
    message: str


def minimise(cost: Callable, gradient: Callable, gauss_newton: Callable, x0: np.ndarray, *,
             max_evaluations: int, ftol: float = 1e-9, stall: float = 1e-4, report: Callable | None = None) -> Minimum:
    """Minimise ``cost`` from ``x0``.

    Parameters
    ----------
    cost : callable ``cost(x) -> (value, state)``
        ``value`` may be inf (a rejected point); ``state`` is handed to ``gradient``.
    gradient : callable ``gradient(x, state) -> ndarray``
        The exact gradient at an accepted point.
    gauss_newton : callable ``gauss_newton(x) -> ndarray (n, n)``
        ``J^T J`` at ``x``: the Hessian approximation at the start, and again whenever ten
        accepted steps in a row lowered the cost by less than ``stall`` (relative) together.
    max_evaluations : int
        Calls of ``cost`` allowed, the one at ``x0`` included.
    ftol : float
        Stop after three accepted steps in a row that each lowered the cost by less than this
        fraction of it.
    report : callable ``report(evaluations, cost)``, optional
        Called after every evaluation with the best cost so far.
    """
    x = np.array(x0, dtype=float)
    f, state = cost(x)
    if not np.isfinite(f):
        return Minimum(x, f, 1, "the starting point has no finite cost")
    g = gradient(x, state)
    H = np.array(gauss_newton(x), dtype=float)
    lam, nu, evaluations, small, recent = 1e-3, 2.0, 1, 0, [f]
    while evaluations < max_evaluations:
        step = _damped_step(H, g, lam)
        if step is None:
            lam, nu = lam * nu, 2 * nu
            continue
        predicted = -(g @ step + 0.5 * step @ H @ step)
        if not predicted > 0:
            return Minimum(x, f, evaluations, "converged: no step predicts a decrease")
        f_new, state_new = cost(x + step)
        evaluations += 1
        rho = (f - f_new) / predicted if np.isfinite(f_new) else -np.inf
        if rho > 1e-4:
            g_new = gradient(x + step, state_new)
            H = _bfgs(H, step, g_new - g)
            small = small + 1 if f - f_new <= ftol * f else 0
            x, f, g = x + step, f_new, g_new
            lam, nu = lam * max(1 / 3, 1 - (2 * rho - 1) ** 3), 2.0
            if small >= 3:
                return Minimum(x, f, evaluations, f"converged: relative decrease below {ftol:g} three times")
            recent.append(f)
            if len(recent) > 10 and recent[-11] - f < stall * f:  # BFGS has lost the curvature: Gauss-Newton again
                H, lam, recent = np.array(gauss_newton(x), dtype=float), 1e-3, [f]
        else:
            lam, nu = lam * nu, 2 * nu
            if lam > 1e20:
                return Minimum(x, f, evaluations, "converged: no further decrease along any damped step")
        if report is not None:
            report(evaluations, f)
    return Minimum(x, f, evaluations, "the maximum number of evaluations is reached")


def _damped_step(H: np.ndarray, g: np.ndarray, lam: float) -> np.ndarray | None:
    """``-(H + lam diag(H))^-1 g`` by Cholesky; None where the damped matrix is not positive definite."""
    diag = np.maximum(np.diag(H), 1e-12 * max(float(np.max(np.diag(H))), 1e-300))
    try:
        factor = scipy.linalg.cho_factor(H + lam * np.diag(diag), check_finite=False)
    except (np.linalg.LinAlgError, ValueError):
        return None
    return -scipy.linalg.cho_solve(factor, g, check_finite=False)


def _bfgs(H: np.ndarray, s: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Powell's damped BFGS update of the Hessian approximation ``H`` (stays positive definite)."""
    Hs = H @ s
    sHs = float(s @ Hs)
    if not sHs > 0:
        return H
    sy = float(s @ y)
    if sy < 0.2 * sHs:  # damping: mix in H s so that the curvature condition holds
        theta = 0.8 * sHs / (sHs - sy)
        y = theta * y + (1 - theta) * Hs
        sy = float(s @ y)
    return H - np.outer(Hs, Hs) / sHs + np.outer(y, y) / sy
