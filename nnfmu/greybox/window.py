"""One window's free run and its forward sensitivities: the CasADi Functions the grey-box problem maps over windows.

``window(x0, U, theta) -> Y`` runs the model's RK4 step from ``x0`` under the inputs ``U``;
``window_derivatives(x0, U, theta) -> (Y, D)`` also carries ``S = dx / d[x0, theta]`` along every RK4
sub-step (forward sensitivities), so that ``D`` holds each output's derivative with respect to the window's
initial state and the free parameters.

Up to :data:`~nnfmu.physics.rk4.UNROLL_MAX` sub-steps a sample, the step and its sensitivity are one SX
graph. More sub-steps (the arm's 50) are the sensitivity of **one** sub-step, an SX Function, folded over the
sub-steps: the graph, and the C code generated from it, stay the size of one sub-step. Differentiating the
folded step as a whole (CasADi's MX Jacobian of the loop, as before) was three times slower in CasADi's
virtual machine and its generated C did not compile within ten minutes.

:func:`~nnfmu.greybox.problem.build_problem` can compile both to C (:func:`nnfmu.physics.compiled.compile_function`;
same values): for the arm with its 12 friction parameters free, the sensitivities took 15 ms a sample
compiled against 112 ms in the virtual machine (and 293 ms differentiating the folded step), after 138 s of
``gcc -O2`` (AMD EPYC, process CPU time, one thread).
"""

from __future__ import annotations

import casadi as ca
import numpy as np

from nnfmu.physics.base import PhysicsSystem
from nnfmu.physics.rk4 import UNROLL_MAX, rk4_function

__all__ = ["window_functions", "sensitivity_step", "compile_worthwhile", "COMPILE_MIN_INSTRUCTIONS"]

#: ODE instructions times RK4 sub-steps from which ``compile="auto"`` compiles the window Functions: the C
#: compiler's seconds pay back within an iteration or two (the arm: 4208 x 50; the valve, 253 x 16, stays).
COMPILE_MIN_INSTRUCTIONS = 20_000


def _sub_sensitivity(system: PhysicsSystem, Ts: float, n_sub: int, select: np.ndarray) -> ca.Function:
    """``(x, S, u, p) -> (x_next, S_next)``: ``n_sub`` RK4 sub-steps over ``Ts``, unrolled, and their sensitivity."""
    step = rk4_function(system.ode, Ts=Ts, n_sub=n_sub, unroll_max=n_sub, name=f"{system.name}_rk4")
    n_x, n_f = system.n_x, select.shape[1]
    x, S = ca.SX.sym("x", n_x), ca.SX.sym("S", n_x, n_x + n_f)
    u, p = ca.SX.sym("u", len(system.inputs)), ca.SX.sym("p", len(system.parameters))
    x_next = step(x, u, p)
    S_next = ca.jacobian(x_next, x) @ S + ca.horzcat(ca.SX(n_x, n_x), ca.jacobian(x_next, p) @ ca.DM(select))
    return ca.Function("sensitivity_step", [x, S, u, p], [x_next, S_next], ["x", "S", "u", "p"], ["x_next", "S_next"])


def sensitivity_step(system: PhysicsSystem, n_sub: int, select: np.ndarray) -> ca.Function:
    """``step(x, S, u, p) -> (x_next, S_next)``: one sample of ``n_sub`` RK4 sub-steps and its forward sensitivity.

    ``S = dx / d[x0, theta]`` (n_x, n_x + n_f); ``dp / dtheta = select`` (n_p, n_f). Module docstring: unrolled
    SX up to UNROLL_MAX sub-steps, else one sub-step's SX sensitivity folded ``n_sub`` times (MX).
    """
    if n_sub <= UNROLL_MAX:
        return _sub_sensitivity(system, system.Ts, n_sub, select)
    sub = _sub_sensitivity(system, system.Ts / n_sub, 1, select)
    n_x, n_f = system.n_x, select.shape[1]
    x, S = ca.MX.sym("x", n_x), ca.MX.sym("S", n_x, n_x + n_f)
    u, p = ca.MX.sym("u", len(system.inputs)), ca.MX.sym("p", len(system.parameters))
    xs, Ss = sub.mapaccum("sub_steps", n_sub, [0, 1], [0, 1])(x, S, ca.repmat(u, 1, n_sub), ca.repmat(p, 1, n_sub))
    return ca.Function("sensitivity_step", [x, S, u, p], [xs[:, -1], Ss[:, -(n_x + n_f):]],
                       ["x", "S", "u", "p"], ["x_next", "S_next"])


def _output_sensitivity(system: PhysicsSystem, select: np.ndarray) -> ca.Function:
    """``out(x, S, p) -> (y, dy)``: the output and its derivative ``dy/d[x0, theta] = dg/dx S + [0, dg/dp select]``."""
    n_x, n_y, n_f = system.n_x, len(system.outputs), select.shape[1]
    x, S, p = ca.SX.sym("x", n_x), ca.SX.sym("S", n_x, n_x + n_f), ca.SX.sym("p", len(system.parameters))
    y = system.output(x, p)
    dy = ca.jacobian(y, x) @ S + ca.horzcat(ca.SX(n_y, n_x), ca.jacobian(y, p) @ ca.DM(select))
    return ca.Function("output_sensitivity", [x, S, p], [y, dy], ["x", "S", "p"], ["y", "dy"])


def window_functions(system: PhysicsSystem, length: int, n_sub: int, base: np.ndarray,
                     select: np.ndarray) -> tuple[ca.Function, ca.Function]:
    """``window(x0[n_x], U[n_u, L-1], theta[n_f]) -> Y[n_y, L]``, one free run from ``x0``, and the same with
    ``-> (Y, D[n_y, L (n_x + n_f)])``, ``D``'s block k being ``dy_k / d[x0, theta]``.

    ``p = base + select theta`` (base: (n_p,), select: (n_p, n_f)).
    """
    n_x, n_f = system.n_x, select.shape[1]
    step = rk4_function(system.ode, Ts=system.Ts, n_sub=n_sub, name=f"{system.name}_rk4")
    x0, theta = ca.MX.sym("x0", n_x), ca.MX.sym("theta", n_f)
    U = ca.MX.sym("U", len(system.inputs), length - 1)
    p = ca.DM(base) + ca.DM(select) @ theta
    P, P1 = ca.repmat(p, 1, length - 1), ca.repmat(p, 1, length)
    X = ca.horzcat(x0, step.mapaccum("run", length - 1)(x0, U, P))
    names = ["x0", "U", "theta"]
    plain = ca.Function("window", [x0, U, theta], [system.output.map(length)(X, P1)], names, ["Y"])
    S0 = ca.horzcat(ca.DM.eye(n_x), ca.DM(n_x, n_f))
    Xs, Ss = sensitivity_step(system, n_sub, select).mapaccum("runs", length - 1, [0, 1], [0, 1])(x0, S0, U, P)
    Y, D = _output_sensitivity(system, select).map(length)(ca.horzcat(x0, Xs), ca.horzcat(S0, Ss), P1)
    return plain, ca.Function("window_derivatives", [x0, U, theta], [Y, D], names, ["Y", "D"])


def compile_worthwhile(system: PhysicsSystem, n_sub: int) -> bool:
    """Whether ``compile="auto"`` compiles: the ODE's instructions times the sub-steps reach
    :data:`COMPILE_MIN_INSTRUCTIONS`."""
    return system.ode.n_instructions() * n_sub >= COMPILE_MIN_INSTRUCTIONS
