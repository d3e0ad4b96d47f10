"""The initial state from an init window: a short least-squares fit of the state, unrolled in CasADi.

A physics model, a grey-box fit or a hybrid starts from its init rule, ``x0 = init(y0, u0)``, which sees
one sample: an unmeasured state (the upper tank's level) can only be guessed (at rest). With an init
window of ``N`` samples, :func:`with_init_window` gives the model an ``init`` that estimates it::

    init(y0, u0[, p], y_past, u_past) -> x0

1. start at the window's oldest sample, ``x_s = init(y_past[0], u_past[0])`` (the model's own rule);
2. run the model's own ``step`` over the window's ``N - 1`` inputs ``u_past`` and compare its outputs with
   the measured ``y_past[1:]`` and ``y0``: residuals ``r = (y_hat - y) / y_scale`` (``(N - 1) n_y`` of them);
3. ``iterations`` Levenberg-Marquardt steps on ``x_s`` (scaled by ``x_scale``), each
   ``dz = -(J^T J + lam (diag(J^T J) + delta I))^-1 J^T r`` with CasADi's exact ``J = dr/dz``, kept only
   where the cost falls (``lam`` / 10), else refused (``lam`` x 10): the cost never rises;
4. ``x0`` is the state at the window's end (the time of ``y0``) of the run from the final ``x_s``.

It is the same criterion as the grey-box fit's per-window state (:mod:`nnfmu.greybox.problem`: simulation
error of a free run from an unknown initial state), at fixed parameters, over the init window.

Everything is CasADi: the loop is unrolled (a fixed number of steps), the linear solve is a symbolic QR of
an ``n_x``-by-``n_x`` SX matrix, and the acceptance is ``if_else``; so it code-generates into the FMU with
no solver library. Guards: a step whose cost is NaN or Inf is refused; if the final cost or state is not
finite (a window of huge values, a model that is NaN there), ``x0`` is the init rule at ``(y0, u0)``, as
without a window.
"""

from __future__ import annotations

import dataclasses

import casadi as ca
import numpy as np

from nnfmu.errors import ShapeError
from nnfmu.limits import MAX_INIT_WINDOW
from nnfmu.physics.rk4 import rk4_step
from nnfmu.system import CasadiModel

__all__ = ["with_init_window", "window_estimator", "lm_estimator", "estimating_model", "compact_step", "ITERATIONS"]

#: Levenberg-Marquardt steps unrolled into ``init``: on the two tanks, noise-free, 10 took the upper level to
#: the true one within 1e-9 from the steady-state guess (tests/test_physics_init_window.py).
ITERATIONS = 10
_LAM0, _LAM_MIN, _LAM_MAX, _DELTA = 1e-2, 1e-9, 1e9, 1e-6
FINITE_LIMIT = 1e300  # larger magnitudes count as not finite (the costs are squares: 1e300 is already absurd)


def _finite(expr):
    """1 where every entry of ``expr`` is finite, else 0: a sum carries NaN (``fmax`` would drop it), and NaN
    fails every comparison."""
    return ca.sum1(ca.fabs(ca.vec(expr))) <= FINITE_LIMIT


def _damped_step(n_x: int) -> ca.Function:
    """``damped_step(JtJ, g, lam) -> dz``: the Levenberg-Marquardt step, a symbolic QR solve (SX)."""
    JtJ, g, lam = ca.SX.sym("JtJ", n_x, n_x), ca.SX.sym("g", n_x), ca.SX.sym("lam")
    A = JtJ + lam * (ca.diag(ca.diag(JtJ)) + _DELTA * ca.SX.eye(n_x))
    return ca.Function("damped_step", [JtJ, g, lam], [-ca.solve(A, g)], ["JtJ", "g", "lam"], ["dz"])


def window_estimator(model: CasadiModel, window: int, *, y_scale=None, x_scale=None,
                     iterations: int = ITERATIONS, step: ca.Function | None = None) -> ca.Function:
    """``estimate(y_win[n_y, N], u_win[n_u, N - 1][, p]) -> (x_end[n_x], x_start[n_x], cost)`` of ``model``.

    ``y_win``: the window's outputs, oldest first, the last being ``y0``; ``u_win``: the inputs between them
    (``u_win[:, j]`` acts from sample ``j`` to ``j + 1``). ``x_start``: the estimated state at the oldest
    sample; ``x_end``: the state at the last (module docstring). ``cost = |r|^2 / 2`` at ``x_start``; ``x_end``
    is not guarded here (:func:`with_init_window` falls back on the init rule).

    ``y_scale`` (n_y,): what each output's error is divided by (default 1, in the output's unit);
    ``x_scale`` (n_x,): the states' typical magnitudes (default 1). ``step``: the model's step written
    otherwise, with its ports (default ``model.step``), e.g. so that its derivative's C code stays small
    (:func:`estimating_model`).
    """
    return lm_estimator(model.init, model.step if step is None else step, window, y_scale=y_scale,
                        x_scale=x_scale, iterations=iterations)


def lm_estimator(init: ca.Function, step: ca.Function, window: int, *, y_scale=None, x_scale=None,
                 iterations: int = ITERATIONS) -> ca.Function:
    """:func:`window_estimator` of the pair ``init(y0, u0[, p]) -> x0``, ``step(x, u[, p]) -> (x_next, y_next)``,
    whose sizes (``n_x``, ``n_u``, ``n_p``, ``n_y``) are read from ``step``'s ports; ``p`` may be any vector both
    take (a hybrid in training passes its physical parameters and its network's weights, :mod:`nnfmu.hybrid.window`).
    """
    n_x, n_u, n_y = step.size1_in(0), step.size1_in(1), step.size1_out(1)
    n_p, n = (step.size1_in(2) if step.n_in() > 2 else 0), window - 1
    y_scale = np.ones(n_y) if y_scale is None else np.asarray(y_scale, dtype=float).ravel()
    x_scale = np.ones(n_x) if x_scale is None else np.asarray(x_scale, dtype=float).ravel()
    if y_scale.shape != (n_y,) or x_scale.shape != (n_x,) or not (np.all(y_scale > 0) and np.all(x_scale > 0)):
        raise ShapeError(f"y_scale and x_scale must be {n_y} and {n_x} positive numbers, got "
                         f"{y_scale.tolist()} and {x_scale.tolist()}")
    Y, U = ca.MX.sym("y_win", n_y, window), ca.MX.sym("u_win", n_u, n)
    p = [ca.MX.sym("p", n_p)] if n_p else []
    z = ca.MX.sym("z", n_x)
    _, Yhat = step.mapaccum("window_run", n, [0], [0])(z * x_scale, U, *(ca.repmat(q, 1, n) for q in p))
    r = ca.vec((Yhat - Y[:, 1:]) / ca.repmat(ca.DM(y_scale), 1, n))
    ins, names = [z, Y, U, *p], ["z", "y_win", "u_win"] + ["p"] * bool(p)
    residuals = ca.Function("window_residuals", ins, [r], names, ["r"])
    # J in one forward sweep of n_x directions. Column by column (one direction mapped over the unit vectors)
    # cut the arm's estimator C from 2.7 to 0.54 MB (gcc 138 -> 88 s) but ran 2.9 times slower (valve, VM)
    linearised = ca.Function("window_jacobian", ins, [r, ca.jacobian(r, z)], names, ["r", "J"])
    damped = _damped_step(n_x)
    zk = init(Y[:, 0], U[:, 0], *p) / x_scale
    cost, lam = 0.5 * ca.sumsqr(residuals(zk, Y, U, *p)), ca.MX(_LAM0)
    for _ in range(iterations):
        rk, J = linearised(zk, Y, U, *p)
        candidate = zk + damped(ca.mtimes(J.T, J), ca.mtimes(J.T, rk), lam)
        new_cost = 0.5 * ca.sumsqr(residuals(candidate, Y, U, *p))
        better = new_cost < cost  # False for NaN: a step into NaN is refused
        zk = ca.if_else(better, candidate, zk)
        cost = ca.if_else(better, new_cost, cost)
        lam = ca.if_else(better, ca.fmax(lam / 10, _LAM_MIN), ca.fmin(lam * 10, _LAM_MAX))
    X, _ = step.mapaccum("window_end", n, [0], [0])(zk * x_scale, U, *(ca.repmat(q, 1, n) for q in p))
    return ca.Function("estimate", [Y, U, *p], [X[:, -1], zk * x_scale, cost],
                       ["y_win", "u_win"] + ["p"] * bool(p), ["x_end", "x_start", "cost"])


def with_init_window(model: CasadiModel, window: int, *, y_scale=None, x_scale=None,
                     iterations: int = ITERATIONS, step: ca.Function | None = None) -> CasadiModel:
    """``model`` with an init window of ``window`` samples whose ``init`` estimates the state (module docstring).

    ``model``: an ``(init, step)`` pair without a window of its own, whose state is what its ``init`` rule
    builds (a physics model, a fit, a hybrid). ``window = 1`` returns ``model`` unchanged. ``y_scale``,
    ``x_scale``, ``iterations``, ``step``: as in :func:`window_estimator`. The FMU takes the window as its
    ``<channel>_past`` parameters (:mod:`nnfmu.window_names`), as a network's init window.
    """
    if isinstance(window, bool) or not isinstance(window, (int, np.integer)) or not 1 <= window <= MAX_INIT_WINDOW:
        raise ShapeError(f"init window must be a whole number of samples from 1 to {MAX_INIT_WINDOW:,} "
                         f"(nnfmu.limits.MAX_INIT_WINDOW), got {window!r}")
    if isinstance(iterations, bool) or not isinstance(iterations, int) or iterations < 0:
        raise ShapeError(f"iterations must be a whole number >= 0, got {iterations!r}")
    if model.spec.init_window != 1:
        raise ShapeError(f"{model.spec.name} already has an init window of {model.spec.init_window} samples")
    if window == 1:
        return model
    window, spec = int(window), model.spec
    estimate = window_estimator(model, window, y_scale=y_scale, x_scale=x_scale, iterations=iterations, step=step)
    n = window - 1
    y0, u0 = ca.MX.sym("y0", spec.n_y), ca.MX.sym("u0", spec.n_u)
    p = [ca.MX.sym("p", spec.n_p)] if spec.n_p else []
    y_past, u_past = ca.MX.sym("y_past", n * spec.n_y), ca.MX.sym("u_past", n * spec.n_u)
    Y = ca.horzcat(ca.reshape(y_past, spec.n_y, n), y0)  # sample by sample, oldest first
    x_end, _, cost = estimate(Y, ca.reshape(u_past, spec.n_u, n), *p)
    ok = ca.logic_and(_finite(x_end), _finite(cost))
    x0 = ca.if_else(ok, x_end, model.init(y0, u0, *p))
    init = ca.Function("init", [y0, u0, *p, y_past, u_past], [x0],
                       ["y0", "u0"] + ["p"] * bool(p) + ["y_past", "u_past"], ["x0"])
    estimator = {"method": "levenberg-marquardt", "iterations": iterations, "window": window}
    source = {**spec.source, "initial_state": estimator}
    return dataclasses.replace(model, init=init, spec=dataclasses.replace(spec, init_window=window, source=source))


def estimating_model(system, *, n_sub: int | None = None, expose_parameters: bool = True, init_window: int = 1,
                     y_scale=None, iterations: int = ITERATIONS) -> CasadiModel:
    """``system.model(...)`` (a :class:`~nnfmu.physics.PhysicsSystem`) with an init window of ``init_window``
    samples whose ``init`` estimates the state (:func:`with_init_window`; ``x_scale``: the states' scales).

    The estimator runs the same RK4 as the model's step, as :func:`compact_step`: the valve's FMU with a
    window of 20 took 133 s to build when the estimator differentiated the model's unrolled SX step (the
    derivative alone was 46,000 lines of C), 80 s so (8.5 s without a window; a loaded machine).
    """
    model = system.model(n_sub=n_sub, expose_parameters=expose_parameters)
    if init_window == 1:
        return model
    step = compact_step(system, n_sub or system.n_sub, expose_parameters=model.spec.n_p > 0)
    return with_init_window(model, init_window, y_scale=y_scale, x_scale=system.state_scales or None,
                            iterations=iterations, step=step)


def compact_step(system, n_sub: int, *, expose_parameters: bool) -> ca.Function:
    """``step(x, u[, p]) -> (x_next, y_next)``: ``n_sub`` RK4 sub-steps of ``system.ode``, as an MX sub-step that
    calls the ODE, folded: its forward derivative's C code holds the ODE's derivative once, not once per stage
    and sub-step. The same arithmetic as :meth:`~nnfmu.physics.PhysicsSystem.model`'s step (to rounding)."""
    n_x, n_u, n_p = system.n_x, len(system.inputs), len(system.parameters)
    x, u, p = ca.MX.sym("x", n_x), ca.MX.sym("u", n_u), ca.MX.sym("p", n_p)
    sub = ca.Function("rk4_sub_step", [x, u, p], [rk4_step(system.ode, x, u, p, Ts=system.Ts / n_sub)],
                      ["x", "u", "p"], ["x_next"])
    advance = sub.fold(n_sub) if n_sub > 1 else sub
    values = p if expose_parameters else ca.DM(system.parameter_values())
    x_next = advance(x, ca.repmat(u, 1, n_sub), ca.repmat(values, 1, n_sub))
    ins, names = ([x, u, p], ["x", "u", "p"]) if expose_parameters else ([x, u], ["x", "u"])
    return ca.Function("estimator_step", ins, [x_next, system.output(x_next, values)], names, ["x_next", "y_next"])
