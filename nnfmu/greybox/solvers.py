"""Minimise ``0.5 |r(z)|^2`` within bounds: SciPy's trust-region reflective least squares, or IPOPT.

Both take the :class:`~nnfmu.greybox.problem.Problem`'s CasADi residuals and exact Jacobian.

- ``"trf"`` (default): :func:`scipy.optimize.least_squares` with ``method="trf"``, bounds on the free
  parameters, the CasADi Jacobian at every iteration. A Gauss-Newton method: it uses the structure of
  a least-squares cost (``J^T J`` for the Hessian), which is all this problem needs.
- ``"ipopt"``: CasADi's ``nlpsol("ipopt")`` on the same cost, an interior point method for general
  constrained problems, given the same Gauss-Newton Hessian ``J^T J`` (from CasADi's own AD of the
  residual graph). IPOPT with CasADi's exact Hessian was slower still: on the slider it had not converged
  after 100 iterations and two minutes.

Measured (benchmarks/greybox_slider.py, docs/greybox.md): on the slider both reach the same cost, trf
in 20 s against 48 s; on the valve trf converges to the true parameters in 21 evaluations (22 s), IPOPT had
not after 100 iterations (8 minutes). trf's Jacobian comes from forward sensitivities carried along the
RK4 steps (:meth:`~nnfmu.greybox.problem.Problem.blocks`), cheaper than CasADi's generic MX Jacobian
that IPOPT evaluates, so trf is the default.

Either way a diverging run (a step into parameters where the free run blows up to NaN or Inf) does not
lose what was found: every evaluation with a finite cost lower than the best so far is kept
(:class:`Tracker`), and the result is the best finite point, with a note saying so.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Callable

import casadi as ca
import numpy as np
from scipy.optimize import least_squares  # loaded before threadpool_limits, so that it limits its BLAS
from threadpoolctl import threadpool_limits

from nnfmu.errors import ConfigError

__all__ = ["SOLVERS", "Tracker", "Outcome", "solve"]

SOLVERS = ("trf", "ipopt")


@dataclass
class Tracker:
    """The best finite point seen: ``cost = 0.5 |r|^2``; ``report(evaluations, cost, best)`` after each."""

    report: Callable[[int, float, float], None] | None = None
    best_cost: float = np.inf
    best_z: np.ndarray | None = None
    evaluations: int = 0
    non_finite: int = 0

    def see(self, z: np.ndarray, r: np.ndarray) -> float:
        self.evaluations += 1
        cost = 0.5 * float(np.dot(r, r)) if np.isfinite(r).all() else np.inf
        if not np.isfinite(cost):
            self.non_finite += 1
        elif cost < self.best_cost:
            self.best_cost, self.best_z = cost, np.array(z, dtype=float)
        if self.report is not None:
            self.report(self.evaluations, cost, self.best_cost)
        return cost


@dataclass(frozen=True)
class Outcome:
    """What one minimisation returned: the best finite ``z``, its cost, and how it went."""

    z: np.ndarray
    cost: float
    evaluations: int
    seconds: float
    status: str
    notes: list[str] = field(default_factory=list)


def _trf(problem, z0, lower, upper, max_evaluations, tracker) -> str:
    def fun(z):
        r = problem.evaluate(z)
        tracker.see(z, r)
        return r if np.isfinite(r).all() else np.full_like(r, np.inf)  # trf shrinks the step on Inf

    # x_scale 1: z is scaled already (module docstring); "jac" crawled on the valve (40 evaluations, not converged,
    # where 1 converged in 20)
    result = least_squares(fun, z0, jac=problem.jacobian, bounds=(lower, upper), method="trf", x_scale=1.0,
                           max_nfev=max_evaluations, tr_solver="exact" if problem.dense else "lsmr")
    return result.message


def _gauss_newton_hessian(z: ca.MX, r: ca.MX) -> ca.Function:
    """IPOPT's ``hess_lag`` as Gauss-Newton's ``lam_f J^T J`` (upper triangle): no second derivatives of the run."""
    lam_f, lam_g, p = ca.MX.sym("lam_f"), ca.MX.sym("lam_g", 0), ca.MX.sym("p", 0)
    J = ca.jacobian(r, z)
    return ca.Function("nlp_hess_l", [z, p, lam_f, lam_g], [lam_f * ca.triu(J.T @ J)],
                       ["x", "p", "lam_f", "lam_g"], ["triu_hess_gamma_x_x"])


def _ipopt(problem, z0, lower, upper, max_evaluations, tracker, *, exact_hessian: bool = False) -> str:
    z = ca.MX.sym("z", problem.n_z)
    r = problem.residuals(z)
    options = {"ipopt.print_level": 0, "print_time": False, "ipopt.sb": "yes", "ipopt.max_iter": int(max_evaluations)}
    if not exact_hessian:
        options["hess_lag"] = _gauss_newton_hessian(z, r)
    solver = ca.nlpsol("greybox", "ipopt", {"x": z, "f": 0.5 * ca.sumsqr(r)}, options)
    big = 1e19  # IPOPT's infinity
    sol = solver(x0=z0, lbx=np.clip(lower, -big, big), ubx=np.clip(upper, -big, big))
    z_end = np.asarray(sol["x"]).ravel()
    tracker.see(z_end, problem.evaluate(z_end))
    stats = solver.stats()
    tracker.evaluations = int(stats.get("iter_count", 0))
    return str(stats.get("return_status", ""))


def solve(problem, z0: np.ndarray, lower: np.ndarray, upper: np.ndarray, *, solver: str = "trf",
          max_evaluations: int = 100, report=None) -> Outcome:
    """Minimise ``0.5 |r(z)|^2`` from ``z0`` within ``lower <= z <= upper`` (arrays (n_z,); +-inf: unbounded).

    ``max_evaluations``: residual evaluations for trf, iterations for IPOPT. ``report(evaluations, cost,
    best)`` is called after every trf evaluation (the progress bar). Returns the best finite point seen.
    """
    if solver not in SOLVERS:
        raise ConfigError(f"unknown solver {solver!r}; choose one of {', '.join(SOLVERS)}")
    tracker = Tracker(report=report)
    tracker.see(z0, problem.evaluate(z0))
    t0 = time.perf_counter()
    with threadpool_limits(1):  # one BLAS thread: ten times faster than two on this problem's small SVDs
        status = (_trf if solver == "trf" else _ipopt)(problem, z0, lower, upper, max_evaluations, tracker)
    notes = []
    if "maximum number" in status.lower() or status == "Maximum_Iterations_Exceeded":
        notes.append(f"the {solver} solver stopped at its limit of {max_evaluations} "
                     f"{'evaluations' if solver == 'trf' else 'iterations'} before converging; raise "
                     "--max-evaluations (or FitConfig.max_evaluations) to go on")
    if tracker.non_finite:
        notes.append(f"{tracker.non_finite} of {tracker.evaluations} evaluations gave NaN or Inf (the free run "
                     "diverged there); the best finite point is kept")
    return Outcome(z=tracker.best_z, cost=tracker.best_cost, evaluations=tracker.evaluations,
                   seconds=time.perf_counter() - t0, status=status, notes=notes)
