"""Issue 37, item 8: the ODE's Jacobian at the rest state of every built-in model, by CasADi's AD, equals finite
differences. Model Exchange starts there and hands this Jacobian to the importer's implicit solver (CVode): the
valve's flow law lost dṗ/dp (0 instead of -0.0101 /s) at the pressure ratio 1 of its start state."""

from __future__ import annotations

import casadi as ca
import numpy as np
import pytest

from nnfmu.physics import resolve_physics


def rest(system):
    """The state the FMU starts from: the init rule at the outputs' and inputs' start values."""
    u = np.array([v.start for v in system.inputs])
    y0 = np.array([v.start for v in system.outputs])
    p = system.parameter_values()
    return np.asarray(system.init_state(y0, u, p), dtype=float).ravel(), u, p


@pytest.mark.parametrize("name", ["valve", "arm", "slider"])
def test_the_odes_jacobian_at_rest_equals_finite_differences(name):
    system = resolve_physics(name)
    x0, u, p = rest(system)
    x = ca.SX.sym("x", len(x0))
    ad = ca.Function("J", [x], [ca.jacobian(system.ode(x, u, p), x)])(x0).full()
    f = lambda xx: np.asarray(system.ode(xx, u, p), dtype=float).ravel()  # noqa: E731
    scales = np.asarray(system.state_scales or np.ones(len(x0)), dtype=float)
    typical = np.abs(ad * scales).max(axis=1)  # per derivative: its change for a typical change of a state
    for j, h in enumerate(1e-6 * np.maximum(np.abs(x0), scales)):
        step = np.eye(len(x0))[j] * h
        forward, backward = (f(x0 + step) - f(x0)) / h, (f(x0) - f(x0 - step)) / h
        central = 0.5 * (forward + backward)
        tol = 1e-4 * np.abs(central) + 1e-8 * typical / scales[j]
        smooth = np.abs(forward - backward) <= tol  # where FD is reliable: both sides agree
        np.testing.assert_array_less(np.abs(ad[:, j] - central)[smooth], tol[smooth] + 1e-300,
                                     err_msg=f"{name}: d(xdot)/d({system.states[j].name}) at rest")


def test_the_valves_derivative_of_pressure_at_ambient_is_the_laminar_slope():
    system = resolve_physics("valve")
    x0, u, p = rest(system)
    i = [v.name for v in system.states].index("p")
    assert x0[i] == pytest.approx(101300.0)  # the ratio 1 across the exhaust pilot
    x = ca.SX.sym("x", len(x0))
    jac = ca.Function("J", [x], [ca.jacobian(system.ode(x, u, p), x)])(x0).full()
    assert jac[i, i] == pytest.approx(-0.0101, rel=0.01)  # measured by central, forward and backward differences
