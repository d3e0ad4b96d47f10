"""Fixed-step classical Runge-Kutta (RK4): the discretisation every physics model is exported with.

The step is written out symbolically, so that it is fully code-generable (no
``cvodes``, no rootfinder) and so that a caller can put anything into the
right-hand side, for example a neural correction of the state derivative in
a hybrid model::

    def rhs(x, u, p):
        return physics.ode(x, u, p) + correction(x, u)

    x_next = rk4_step(rhs, x, u, p, Ts=system.Ts, n_sub=4)

The input ``u`` is held constant over the sample period (zero-order hold), as
the dataset convention says (``u[k]`` acts over ``[t_k, t_k + Ts)``).
"""

from __future__ import annotations

from typing import Callable

import casadi as ca

from nnfmu.errors import ConfigError

__all__ = ["rk4_step", "rk4_function", "physics_step", "UNROLL_MAX"]

UNROLL_MAX = 8  # sub-steps unrolled into one SX graph; more become a folded loop


def rk4_step(rhs: Callable, x, u, p, *, Ts: float, n_sub: int = 1):
    """Advance ``x`` by one sample period ``Ts`` with ``n_sub`` RK4 sub-steps of ``Ts / n_sub``.

    Parameters
    ----------
    rhs : callable ``rhs(x, u, p) -> xdot``
        Continuous-time right-hand side, e.g. a :class:`casadi.Function` with
        ports ``(x, u, p) -> xdot`` or any Python callable of CasADi or numpy values.
    x : SX, MX, DM or ndarray, shape (n_x, 1)
        State at ``t``.
    u : shape (n_u, 1)
        Input, held constant over ``[t, t + Ts)``.
    p : shape (n_p, 1)
        Parameters, passed through to ``rhs`` unchanged.
    Ts : float
        Sample period in seconds.
    n_sub : int
        Number of equal RK4 sub-steps (>= 1).

    Returns
    -------
    Same type as ``rhs`` returns, shape (n_x, 1): the state at ``t + Ts``.
    """
    if int(n_sub) != n_sub or n_sub < 1:
        raise ConfigError(f"n_sub must be a positive integer number of RK4 sub-steps, got {n_sub!r}")
    if not Ts > 0:
        raise ConfigError(f"Ts must be a positive sample time in seconds, got {Ts!r}")
    h = float(Ts) / int(n_sub)
    for _ in range(int(n_sub)):
        k1 = rhs(x, u, p)
        k2 = rhs(x + 0.5 * h * k1, u, p)
        k3 = rhs(x + 0.5 * h * k2, u, p)
        k4 = rhs(x + h * k3, u, p)
        x = x + (h / 6.0) * (k1 + 2.0 * k2 + 2.0 * k3 + k4)
    return x


def rk4_function(ode: ca.Function, *, Ts: float, n_sub: int = 1, name: str = "rk4",
                 unroll_max: int = UNROLL_MAX) -> ca.Function:
    """The Function ``name(x, u, p) -> x_next``: :func:`rk4_step` over the ``ode`` Function.

    ``ode`` must have ports ``(x, u, p) -> xdot``. Up to ``unroll_max`` sub-steps
    are unrolled into one SX expression (fastest for small models). More
    sub-steps become a loop: one SX sub-step Function folded ``n_sub`` times
    (an MX Function), so the graph and the generated C stay the size of one
    sub-step. Both are code-generable and give the same numbers.
    """
    if int(n_sub) != n_sub or n_sub < 1:
        raise ConfigError(f"n_sub must be a positive integer number of RK4 sub-steps, got {n_sub!r}")
    n_x, n_u, n_p = ode.size1_in(0), ode.size1_in(1), ode.size1_in(2)
    x, u, p = ca.SX.sym("x", n_x), ca.SX.sym("u", n_u), ca.SX.sym("p", n_p)
    if n_sub <= unroll_max:
        x_next = rk4_step(ode, x, u, p, Ts=Ts, n_sub=int(n_sub))
        return ca.Function(name, [x, u, p], [x_next], ["x", "u", "p"], ["x_next"])
    sub = ca.Function(f"{name}_sub", [x, u, p], [rk4_step(ode, x, u, p, Ts=Ts / n_sub)],
                      ["x", "u", "p"], ["x_next"])
    loop = sub.fold(int(n_sub))
    xm, um, pm = ca.MX.sym("x", n_x), ca.MX.sym("u", n_u), ca.MX.sym("p", n_p)
    x_next = loop(xm, ca.repmat(um, 1, int(n_sub)), ca.repmat(pm, 1, int(n_sub)))
    return ca.Function(name, [xm, um, pm], [x_next], ["x", "u", "p"], ["x_next"])


def physics_step(system, Ts: float, n_sub: int) -> ca.Function:
    """``{name}_rk4(x, u, p) -> x_next``: :func:`rk4_step` over calls of ``system.ode`` (a PhysicsSystem).

    An MX graph that calls ``system.ode`` ``4 n_sub`` times, so its C code (and that of its
    reverse mode) holds the ODE once, not ``4 n_sub`` inlined copies: it compiles in about
    a second instead of ten (valve) and stays small for the arm's 50 sub-steps.
    """
    x = ca.MX.sym("x", system.n_x)
    u, p = ca.MX.sym("u", len(system.inputs)), ca.MX.sym("p", len(system.parameters))
    x_next = rk4_step(system.ode, x, u, p, Ts=Ts, n_sub=n_sub)
    return ca.Function(f"{system.name}_rk4", [x, u, p], [x_next], ["x", "u", "p"], ["x_next"])
