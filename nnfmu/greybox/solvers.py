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

When to stop. Without a limit from the user (``max_evaluations=None``) a fit runs until it converges:
trf stops when a step lowers the cost by less than :data:`FTOL` of itself (SciPy's ``ftol``), moves the
scaled unknowns by less than ``1e-8`` of their size (``xtol``) or the gradient vanishes (``gtol``);
:data:`DEFAULT_MAX_EVALUATIONS` is only a guard. :attr:`Outcome.reason` says in one line why it stopped.
:data:`FTOL` chosen on validation, two tanks of docs/own-physics.md (upper tank unmeasured, 1 % noise):
at SciPy's ``ftol = 1e-8`` the fit with the redundant ``A1`` and ``a1`` free crawled along their valley for
942 evaluations (166 on 16 records), past the old limit of 100 (issue 34); at ``1e-6`` it stopped after 216
(94) with the same validation NRMSE to four digits (0.007032 against 0.007034; 0.008832 against 0.008829),
and the well-posed fits stopped at the same point either way (22 and 24 evaluations).
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

__all__ = ["SOLVERS", "Tracker", "Outcome", "solve", "DEFAULT_MAX_EVALUATIONS", "FTOL"]

SOLVERS = ("trf", "ipopt")

#: Residual evaluations (trf) or iterations (IPOPT) per start when the user sets no limit: a guard against a
#: run that never settles, not a budget (module docstring).
DEFAULT_MAX_EVALUATIONS = 1000

#: trf stops when a step lowers the cost by less than this fraction of it (SciPy's ``ftol``).
FTOL = 1e-6


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
    converged: bool = False
    reason: str = ""


def _trf(problem, z0, lower, upper, max_evaluations, tracker) -> tuple[str, int]:
    def fun(z):
        r = problem.evaluate(z)
        tracker.see(z, r)
        return r if np.isfinite(r).all() else np.full_like(r, np.inf)  # trf shrinks the step on Inf

    # x_scale 1: z is scaled already (module docstring); "jac" crawled on the valve (40 evaluations, not converged,
    # where 1 converged in 20)
    result = least_squares(fun, z0, jac=problem.jacobian, bounds=(lower, upper), method="trf", x_scale=1.0,
                           max_nfev=max_evaluations, ftol=FTOL, tr_solver="exact" if problem.dense else "lsmr")
    return result.message, int(result.status)


def _gauss_newton_hessian(z: ca.MX, r: ca.MX) -> ca.Function:
    """IPOPT's ``hess_lag`` as Gauss-Newton's ``lam_f J^T J`` (upper triangle): no second derivatives of the run."""
    lam_f, lam_g, p = ca.MX.sym("lam_f"), ca.MX.sym("lam_g", 0), ca.MX.sym("p", 0)
    J = ca.jacobian(r, z)
    return ca.Function("nlp_hess_l", [z, p, lam_f, lam_g], [lam_f * ca.triu(J.T @ J)],
                       ["x", "p", "lam_f", "lam_g"], ["triu_hess_gamma_x_x"])


def _ipopt(problem, z0, lower, upper, max_evaluations, tracker, *, exact_hessian: bool = False) -> tuple[str, int]:
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
    status = str(stats.get("return_status", ""))
    code = {"Solve_Succeeded": 1, "Solved_To_Acceptable_Level": 1, "Maximum_Iterations_Exceeded": 0}.get(status, -1)
    return status, code


#: trf's termination codes (scipy.optimize.least_squares ``status``) in words; 0 is the evaluation limit.
_TRF_REASONS = {1: "the gradient vanished (gtol)", 2: f"a step lowered the cost by less than {FTOL:g} of it (ftol)",
                3: "a step moved the unknowns by less than 1e-8 of their size (xtol)",
                4: f"a step lowered the cost by less than {FTOL:g} of it and moved the unknowns by less than 1e-8"}


def _reason(solver: str, status: str, code: int, limit: int, user_limit: bool, evaluations: int) -> str:
    """One line: why the solver stopped."""
    unit = "evaluations" if solver == "trf" else "iterations"
    if code == 0:
        if user_limit:
            return (f"stopped at the limit of {limit} {unit} that --max-evaluations set, before converging; "
                    "raise it or leave it out to run until converged")
        return (f"stopped at the default guard of {limit} {unit} without converging (the cost still falls); "
                "see the identifiability lines, or raise --max-evaluations")
    if code > 0:
        why = _TRF_REASONS.get(code, status) if solver == "trf" else f"IPOPT: {status}"
        return f"converged after {evaluations} {unit}: {why}"
    return f"stopped after {evaluations} {unit} without converging: {status}"


def solve(problem, z0: np.ndarray, lower: np.ndarray, upper: np.ndarray, *, solver: str = "trf",
          max_evaluations: int | None = None, report=None) -> Outcome:
    """Minimise ``0.5 |r(z)|^2`` from ``z0`` within ``lower <= z <= upper`` (arrays (n_z,); +-inf: unbounded).

    ``max_evaluations``: residual evaluations for trf, iterations for IPOPT (None: until converged, within
    :data:`DEFAULT_MAX_EVALUATIONS`). ``report(evaluations, cost, best)`` is called after every trf evaluation
    (the progress bar). Returns the best finite point seen, with why the solver stopped.
    """
    if solver not in SOLVERS:
        raise ConfigError(f"unknown solver {solver!r}; choose one of {', '.join(SOLVERS)}")
    tracker = Tracker(report=report)
    tracker.see(z0, problem.evaluate(z0))
    limit = DEFAULT_MAX_EVALUATIONS if max_evaluations is None else int(max_evaluations)
    t0 = time.perf_counter()
    with threadpool_limits(1):  # one BLAS thread: ten times faster than two on this problem's small SVDs
        status, code = (_trf if solver == "trf" else _ipopt)(problem, z0, lower, upper, limit, tracker)
    reason = _reason(solver, status, code, limit, max_evaluations is not None, tracker.evaluations)
    notes = [] if code > 0 else [f"the {solver} solver {reason}"]
    if tracker.non_finite:
        notes.append(f"{tracker.non_finite} of {tracker.evaluations} evaluations gave NaN or Inf (the free run "
                     "diverged there); the best finite point is kept")
    return Outcome(z=tracker.best_z, cost=tracker.best_cost, evaluations=tracker.evaluations,
                   seconds=time.perf_counter() - t0, status=status, notes=notes, converged=code > 0, reason=reason)
