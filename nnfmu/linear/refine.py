"""Refinement of a linear model on its free-run simulation error (an output-error fit).

It minimises the sum of squared normalised output errors of free runs over every training
trajectory (the sample ``k = 0``, which is the measured ``y0`` by contract, excluded), by one
of two methods:

- ``"quasi-newton"`` (default): :mod:`nnfmu.linear.quasi_newton` with costs by free runs and
  exact gradients by the adjoint pass (:mod:`nnfmu.linear.adjoint`): an evaluation costs two
  free runs, so thousands fit in the time of a hundred Gauss-Newton evaluations;
- ``"gauss-newton"``: ``scipy.optimize.least_squares`` (trust-region reflective) on the
  compressed problem below: every evaluation forms ``J^T J`` (one pass per parameter direction).

Initial states (``x0``):

- ``"rule"``: each run starts where the model's own ``init`` rule puts it, so
  the fit optimises exactly what is scored;
- ``"fit"``: each training trajectory's initial state is a free nuisance
  parameter, eliminated by variable projection (Golub-Pereyra, with
  Kaufman's Jacobian), for trajectories that do not start where the rule
  assumes (pieces cut out of a longer record, not at rest).

Parameters. ``A``, ``B``, ``C`` (and ``b`` for the ``estimate`` rule) move in
*data-driven local coordinates* (McKelvey): only directions orthogonal to the
manifold of similar systems ``(T^-1 A T, T^-1 B, C T)`` at the start, which
removes the ``n^2`` directions that change the state basis but not the outputs.
The Jacobian comes from forward sensitivities (exact, one pass over the data);
only the ``estimate`` rule's initial state is differentiated by central
differences.

Size. The full residual vector of the robot benchmark has 2e5 entries and
its Jacobian 3e7; factorising it would dominate the run time. The pass over
the data therefore accumulates only ``J^T J``, ``J^T r`` and ``r^T r``, and
``least_squares`` receives an equivalent compressed problem ``(r_c, J_c)`` with
``J_c^T J_c = J^T J``, ``J_c^T r_c = J^T r`` and ``|r_c| = |r|``. Its cost, gradient
and Gauss-Newton model are those of the full problem, so it takes the same steps.

Early stop on validation (``early_stop``, what :func:`nnfmu.linear.identify_linear` does). A
lower training cost is not a better model: on short or noisy records the free-run fit goes on
lowering the training cost while the validation error rises. With an :class:`EarlyStop`, the
system with the lowest training cost so far is scored on validation every ``every``
evaluations; the refinement stops once ``patience`` checks in a row found no better score, and
returns the best-scoring system seen (the start included, so it never returns a worse one).

Stability. The residual function returns a fixed penalty (ten times the
starting residual norm) for any ``A`` whose spectral radius reaches
``max_radius``; the trust region rejects that step and shrinks, so every
accepted iterate, and hence the result, is stable.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass
from typing import Callable

import numpy as np
import scipy.linalg.blas
import scipy.optimize

from nnfmu.errors import ConfigError
from nnfmu.linear.adjoint import minimise_output_error
from nnfmu.linear.early_stop import EarlyStop, _Monitor, _Stopped
from nnfmu.linear.statespace import StateSpace, free_run, init_gains, padded

X0_OPTIONS = ("rule", "fit")
METHODS = ("quasi-newton", "gauss-newton")
_FD_STEP = 1e-6
_CHUNK_SIZE = 2_000_000  # sensitivity values held per time chunk (16 MB)


@dataclass(frozen=True)
class RefineResult:
    """The refined system, the cost (half the sum of squared residuals) before and after, and evaluations.

    With an :class:`EarlyStop`, ``score_before`` and ``score_after`` are the validation scores of the
    start and of the returned system, ``best_evaluation`` the evaluation that found it (0: the start)
    and ``score_last``, ``cost_last`` the score and cost of the last system checked (None: none was).
    """

    system: StateSpace
    cost_before: float
    cost_after: float
    evaluations: int
    message: str
    score_before: float | None = None
    score_after: float | None = None
    best_evaluation: int | None = None
    score_last: float | None = None
    cost_last: float | None = None


def _directions(sys: StateSpace, with_b: bool) -> np.ndarray:
    """Orthonormal basis (n_params, n_dir) of parameter moves orthogonal to similarity transforms."""
    n = sys.n_x
    tangent = []
    for i in range(n):
        for j in range(n):
            X = np.zeros((n, n))
            X[i, j] = 1.0
            parts = [sys.A @ X - X @ sys.A, -X @ sys.B, sys.C @ X] + ([-X @ sys.b] if with_b else [])
            tangent.append(np.concatenate([p.ravel() for p in parts]))
    left, sv, _ = np.linalg.svd(np.array(tangent).T, full_matrices=True)
    rank = int(np.sum(sv > 1e-10 * sv[0])) if sv.size and sv[0] > 0 else 0
    return left[:, rank:]


def _compress(gram: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(r_c, J_c)`` from the Gram matrix of ``[J r]``: same ``J^T J``, ``J^T r`` and ``|r|``."""
    n_dir = gram.shape[0] - 1
    lam, vec = np.linalg.eigh(gram[:n_dir, :n_dir])
    keep = lam > 1e-13 * max(lam[-1], 1e-300)
    root = np.sqrt(lam[keep])
    jac = np.zeros((n_dir + 1, n_dir))
    jac[:keep.sum()] = root[:, None] * vec[:, keep].T
    res = np.zeros(n_dir + 1)
    res[:keep.sum()] = (vec[:, keep].T @ gram[:n_dir, n_dir]) / root
    res[-1] = np.sqrt(max(gram[n_dir, n_dir] - res[:-1] @ res[:-1], 0.0))
    return res, jac


class _Problem:
    """Compressed residuals and Jacobian of the free-run error, in the coordinates ``beta``."""

    def __init__(self, sys: StateSpace, us, ys, init: str, x0: str, max_radius: float, report=None):
        self.start, self.init, self.fit_x0, self.max_radius = sys, init, x0 == "fit", max_radius
        self.report, self.evaluations, self.best, self.monitor = report, 0, np.inf, None
        self.with_b = init == "estimate"
        n, n_u, n_y = sys.n_x, sys.B.shape[1], sys.C.shape[0]
        self.shapes = [(n, n), (n, n_u), (n_y, n)]
        self.theta0 = np.concatenate([sys.A.ravel(), sys.B.ravel(), sys.C.ravel()] + ([sys.b] if self.with_b else []))
        self.basis = _directions(sys, self.with_b)
        self.u, mask = padded(list(us))
        self.y, _ = padded(list(ys))
        self.mask = mask.copy()
        self.mask[:, 0] = False  # y[0] is the measured y0 by contract, not a prediction
        self.cache: tuple = (None, None, None)
        self.penalty = None
        res, _ = self.evaluate(np.zeros(self.n_dir))
        self.cost0 = 0.5 * float(res @ res)
        self.penalty = np.zeros_like(res)
        self.penalty[-1] = 10.0 * np.sqrt(2.0 * self.cost0) + 1.0

    @property
    def n_dir(self) -> int:
        return self.basis.shape[1]

    def system(self, beta: np.ndarray) -> StateSpace:
        theta = self.theta0 + self.basis @ beta
        parts, at = [], 0
        for shape in self.shapes:
            parts.append(theta[at:at + shape[0] * shape[1]].reshape(shape))
            at += shape[0] * shape[1]
        b = theta[at:] if self.with_b else self.start.b
        return StateSpace(parts[0], parts[1], b, parts[2], self.start.d)

    def residuals(self, beta: np.ndarray) -> np.ndarray:
        return self.evaluate(beta)[0]

    def jacobian(self, beta: np.ndarray) -> np.ndarray:
        return self.evaluate(beta)[1]

    def evaluate(self, beta: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        key = beta.tobytes()
        if self.cache[0] != key:
            sys = self.system(beta)
            if self.penalty is not None and not sys.spectral_radius < self.max_radius:
                out = (self.penalty, np.zeros((self.n_dir + 1, self.n_dir)))
            else:
                out = _compress(self._gram(sys, beta))
                if self.penalty is not None and not np.isfinite(out[0]).all():
                    out = (self.penalty, np.zeros((self.n_dir + 1, self.n_dir)))
            self.cache = (key, *out)
            self._count(0.5 * float(out[0] @ out[0]), sys)
        return self.cache[1], self.cache[2]

    def _count(self, cost: float, sys: StateSpace | None = None) -> None:
        """Count one evaluation of ``sys`` (None: not kept) at ``cost``; may raise _Stopped (early stop)."""
        if self.penalty is None:  # the starting point, evaluated in __init__, is not an evaluation of the fit
            return
        self.evaluations += 1
        self.best = min(self.best, cost)
        if self.report is not None:
            self.report(self.evaluations, cost, self.best)
        if self.monitor is not None:
            self.monitor.seen(self.evaluations, cost, sys)

    def _rule_x0(self, sys: StateSpace) -> np.ndarray:
        if self.init == "zero-offset":
            return np.zeros((len(self.u), sys.n_x))
        K_y, K_u, k_0 = init_gains(sys)
        return (self.y[:, 0] - sys.d) @ K_y.T + self.u[:, 0] @ K_u.T + k_0

    def _rule_x0_sensitivity(self, beta: np.ndarray) -> np.ndarray:
        sens = np.zeros((len(self.u), self.start.n_x, self.n_dir))
        if self.init == "zero-offset":
            return sens
        for q in range(self.n_dir):
            step = np.zeros(self.n_dir)
            step[q] = _FD_STEP
            plus, minus = self._rule_x0(self.system(beta + step)), self._rule_x0(self.system(beta - step))
            sens[:, :, q] = (plus - minus) / (2 * _FD_STEP)
        return sens

    def _fitted_x0(self, sys: StateSpace) -> np.ndarray:
        """Least-squares initial state of each trajectory for the current system."""
        _, y_forced = free_run(sys, np.zeros((len(self.u), sys.n_x)), self.u)
        obs = _observability(sys, self.u.shape[1])  # (N, n_y, n)
        x0 = np.empty((len(self.u), sys.n_x))
        for i, rows in enumerate(self.mask):
            x0[i] = np.linalg.lstsq(obs[rows].reshape(-1, sys.n_x),
                                    (self.y[i] - y_forced[i])[rows].ravel(), rcond=None)[0]
        return x0

    @functools.cached_property
    def _moves(self) -> list[np.ndarray]:
        """Per block A, B, C: a matrix M with ``(v @ M).reshape(rows, n_dir)[:, q] = dBlock_q @ v``."""
        out, at = [], 0
        for rows, cols in self.shapes:
            block = self.basis[at:at + rows * cols].reshape(rows, cols, self.n_dir)
            out.append(block.transpose(1, 0, 2).reshape(cols, rows * self.n_dir))
            at += rows * cols
        return out

    def _gram(self, sys: StateSpace, beta: np.ndarray) -> np.ndarray:
        """Gram matrix of ``[J r]`` (projected on the x0 complement for ``fit``), by forward sensitivities."""
        n, n_dir, batch, n_steps = sys.n_x, self.n_dir, self.u.shape[0], self.u.shape[1]
        if self.fit_x0:
            x0, sens = self._fitted_x0(sys), np.zeros((n, batch, n_dir))
        else:
            x0, sens = self._rule_x0(sys), self._rule_x0_sensitivity(beta).transpose(1, 0, 2).copy()
        xs, yhat = free_run(sys, x0, self.u)
        resid = (yhat - self.y) * self.mask[:, :, None]
        obs = _observability(sys, n_steps) if self.fit_x0 else None
        width = (n if self.fit_x0 else 0) + n_dir + 1
        # per trajectory only where its initial state is eliminated; otherwise one sum over every row
        gram = np.zeros((batch if self.fit_x0 else 1, width, width), order="F")
        chunk = int(np.clip(_CHUNK_SIZE // (n * batch * n_dir), 1, n_steps))
        for start in range(0, n_steps, chunk):
            span = slice(start, min(start + chunk, n_steps))
            block, sens = self._chunk_rows(sys, xs[:, span], self.u[:, span], sens)
            parts = ([np.broadcast_to(obs[span], (batch,) + obs[span].shape)] if self.fit_x0 else [])
            block = np.concatenate(parts + [block, resid[:, span, :, None]], axis=3)
            block = (block * self.mask[:, span, None, None]).reshape(len(gram), -1, width)
            for i in range(len(gram)):  # BLAS's symmetric rank-k update: half the products of B^T B
                gram[i] = _syrk(block[i].T, gram[i])
        gram = np.triu(gram) + np.triu(gram, 1).transpose(0, 2, 1)
        if self.fit_x0:  # Schur complement: eliminate the initial states
            g_oo, g_or = gram[:, :n, :n], gram[:, :n, n:]
            gram = gram[:, n:, n:] - g_or.transpose(0, 2, 1) @ np.linalg.pinv(g_oo, rcond=1e-12) @ g_or
        return gram.sum(axis=0)

    def _chunk_rows(self, sys: StateSpace, xs: np.ndarray, us: np.ndarray, sens: np.ndarray):
        """Output sensitivities (batch, T, n_y, n_dir) over a time chunk, and the state sensitivity after it.

        ``sens`` (n, batch, n_dir) is d x / d beta at the chunk's first step; ``xs`` (batch, T, n) and
        ``us`` (batch, T, n_u) are the states and inputs over the chunk.
        """
        n, n_y, n_dir = sys.n_x, sys.C.shape[0], self.n_dir
        batch, steps = xs.shape[:2]
        move_A, move_B, move_C = self._moves
        forcing = (xs @ move_A + us @ move_B).reshape(batch, steps, n, n_dir)
        if self.with_b:
            forcing += self.basis[-n:]
        forcing = np.ascontiguousarray(forcing.transpose(1, 2, 0, 3)).reshape(steps, n, batch * n_dir)
        history = np.empty((steps, n, batch * n_dir))
        state = sens.reshape(n, batch * n_dir)
        for t in range(steps):  # the only per-step loop: one matrix product
            history[t] = state
            state = sys.A @ state + forcing[t]
        rows = (sys.C @ history).reshape(steps, n_y, batch, n_dir).transpose(2, 0, 1, 3)
        rows = rows + (xs @ move_C).reshape(batch, steps, n_y, n_dir)
        return rows, state.reshape(n, batch, n_dir)


def _syrk(a_t: np.ndarray, acc: np.ndarray) -> np.ndarray:
    """``acc + a_t @ a_t.T`` in the upper triangle (``a_t`` (k, rows), F-ordered ``acc`` (k, k)): BLAS ``dsyrk``."""
    return scipy.linalg.blas.dsyrk(1.0, a_t, beta=1.0, c=acc, trans=0, lower=0, overwrite_c=True)


def _observability(sys: StateSpace, n_steps: int) -> np.ndarray:
    """``C A^k`` for ``k = 0 .. n_steps-1``, shape (n_steps, n_y, n)."""
    out = np.empty((n_steps,) + sys.C.shape)
    out[0] = sys.C
    for k in range(1, n_steps):
        out[k] = out[k - 1] @ sys.A
    return out


def refine(sys: StateSpace, us, ys, *, init: str, x0: str = "rule", max_radius: float, max_evaluations: int,
           method: str = "quasi-newton", report: Callable[[int, float, float], None] | None = None,
           early_stop: EarlyStop | None = None) -> RefineResult:
    """Fit ``sys`` to normalised trajectories by free-run output error.

    Parameters
    ----------
    sys : StateSpace
        Starting point, normalised coordinates; spectral radius below ``max_radius``.
    us, ys : sequences of arrays (n_steps_i, n_u), (n_steps_i, n_y)
        Normalised training trajectories (for ``zero-offset``: offset by their initial values).
    init : {"estimate", "zero-offset"}
        The model's initial-state rule (``estimate`` also refines ``b``).
    x0 : {"rule", "fit"}
        Start each training run by the rule, or fit each trajectory's initial state.
    max_radius : float
        Spectral radius that no accepted ``A`` may reach.
    max_evaluations : int
        Cost evaluations allowed (a free run for ``quasi-newton``, ``J^T J`` for ``gauss-newton``).
    method : {"quasi-newton", "gauss-newton"}
        The minimiser (module docstring).
    report : callable, optional
        ``report(evaluations, cost, best_cost)`` after every evaluation (progress display).
    early_stop : EarlyStop, optional
        Score on validation while refining, stop when the score stops improving, and return the
        best-scoring system (module docstring). None: run to convergence or ``max_evaluations``.
    """
    if not sys.spectral_radius < max_radius:
        raise ConfigError(f"refinement must start from a stable system, got spectral radius {sys.spectral_radius:.6g} "
                          f">= max_radius {max_radius}; pull the eigenvalues in first (nnfmu.linear.stabilise)")
    for name, value, allowed in (("x0", x0, X0_OPTIONS), ("method", method, METHODS)):
        if value not in allowed:
            raise ConfigError(f"{name} must be one of {', '.join(allowed)}, got {value!r}")
    problem = _Problem(sys, us, ys, init, x0, max_radius, report)
    if problem.n_dir == 0:
        return RefineResult(sys, problem.cost0, problem.cost0, 0, "nothing to refine")
    if early_stop is not None:
        problem.monitor = _Monitor(early_stop, sys, problem.cost0)
    try:
        if method == "quasi-newton":
            found = minimise_output_error(problem, max_evaluations)
            beta, cost, evaluations, message = found.x, found.cost, found.evaluations, found.message
        else:
            result = scipy.optimize.least_squares(problem.residuals, np.zeros(problem.n_dir), jac=problem.jacobian,
                                                  method="trf", x_scale="jac", max_nfev=max_evaluations)
            beta, cost, evaluations, message = result.x, float(result.cost), int(result.nfev), result.message
    except _Stopped:
        return _best_scored(problem, None)
    if problem.monitor is not None:
        return _best_scored(problem, (beta, cost, message))
    refined = problem.system(beta)
    if not refined.spectral_radius < max_radius or cost > problem.cost0:
        return RefineResult(sys, problem.cost0, problem.cost0, evaluations, f"rejected ({message})")
    return RefineResult(refined, problem.cost0, cost, evaluations, message + _at_limit(refined, max_radius))


def _at_limit(system: StateSpace, max_radius: float) -> str:
    """The note that tells the user why a fit ended at the stability limit (empty if it did not)."""
    if system.spectral_radius > max_radius - 1e-4 * max_radius:
        return " Stopped at the spectral-radius limit: the fit pulls towards an unstable model."
    return ""


def _best_scored(problem: _Problem, end: tuple | None) -> RefineResult:
    """The early-stopped result: the best-scoring system seen. ``end``: ``(beta, cost, message)`` where the
    minimiser ended by itself (its end point is a candidate too), None where validation stopped it."""
    monitor, n = problem.monitor, problem.evaluations
    if end is not None:
        beta, cost, why = end
        system = problem.system(beta)
        if cost < monitor.train_best and system.spectral_radius < problem.max_radius:
            monitor.candidate, monitor.scored = (system, cost, n), False
        monitor.check()
    else:
        why = (f"stopped: the validation score did not improve in {monitor.rule.patience} checks "
               f"({monitor.rule.patience * monitor.rule.every} evaluations)")
    score, system, cost, at = monitor.best
    found = f"best validation score at evaluation {at}" if at else "no evaluation scored better than the start"
    message = f"{why}; {found}." + _at_limit(system, problem.max_radius)
    return RefineResult(system, problem.cost0, cost, n, message, monitor.score0, score, at,
                        *(monitor.last or (None, None)))
