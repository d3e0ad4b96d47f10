"""The smooth helpers for ModelBuilder files (nnfmu.physics.smooth, issue 34 item 7): CasADi's derivative at each
kink is the analytic one (finite, no NaN), it equals central differences away from the kink, the documented error
bounds against the sharp functions hold, and a model written with them fits and steps through its kink."""

from __future__ import annotations

import casadi as ca
import numpy as np
import pytest

from nnfmu.physics.smooth import (ERROR_BOUNDS, smooth_abs, smooth_clip, smooth_max, smooth_min, smooth_sign,
                                  smooth_sqrt)

EPS = 0.01
#: helper of one argument x (the others fixed: b = 0.3 for max and min, [lo, hi] = [-0.5, 0.5] for clip), its kink,
#: and the analytic derivative there
CASES = {
    "smooth_sign": (lambda x: smooth_sign(x, EPS), 0.0, 1 / EPS),
    "smooth_abs": (lambda x: smooth_abs(x, EPS), 0.0, 0.0),
    "smooth_sqrt": (lambda x: smooth_sqrt(x, EPS), 0.0, 1 / np.sqrt(EPS)),
    "smooth_max": (lambda x: smooth_max(x, 0.3, EPS), 0.3, 0.5),
    "smooth_min": (lambda x: smooth_min(x, 0.3, EPS), 0.3, 0.5),
    "smooth_clip_lo": (lambda x: smooth_clip(x, -0.5, 0.5, EPS), -0.5, 0.5),
    "smooth_clip_hi": (lambda x: smooth_clip(x, -0.5, 0.5, EPS), 0.5, 0.5),
}
SHARP = {
    "smooth_sign": np.sign, "smooth_abs": np.abs, "smooth_sqrt": lambda x: np.sign(x) * np.sqrt(np.abs(x)),
    "smooth_max": lambda x: np.maximum(x, 0.3), "smooth_min": lambda x: np.minimum(x, 0.3),
    "smooth_clip_lo": lambda x: np.clip(x, -0.5, 0.5), "smooth_clip_hi": lambda x: np.clip(x, -0.5, 0.5),
}


def _value_and_slope(name):
    f = CASES[name][0]
    x = ca.SX.sym("x")
    e = f(x)
    fun = ca.Function(name, [x], [e, ca.jacobian(e, x)])
    return lambda v: tuple(float(o) for o in fun(v))


@pytest.mark.parametrize("name", CASES)
def test_the_derivative_at_the_kink_is_the_analytic_one(name):
    _, kink, slope = CASES[name]
    value, ad = _value_and_slope(name)(kink)
    assert np.isfinite(value) and np.isfinite(ad)
    assert ad == pytest.approx(slope, rel=1e-6, abs=1e-9)
    if name != "smooth_sqrt":  # the sharp signed sqrt's own derivative at 0 is NaN in CasADi: why the helper exists
        return
    x = ca.SX.sym("x")
    sharp = ca.Function("sharp", [x], [ca.jacobian(ca.sign(x) * ca.sqrt(ca.fabs(x)), x)])
    assert not np.isfinite(float(sharp(0.0)))


@pytest.mark.parametrize("name", CASES)
def test_the_derivative_equals_central_differences_around_the_kink(name):
    _, kink, _ = CASES[name]
    f = _value_and_slope(name)
    for offset in (-5 * EPS, -0.7 * EPS, 0.3 * EPS, 2 * EPS, 40 * EPS):
        x, h = kink + offset, 1e-6
        central = (f(x + h)[0] - f(x - h)[0]) / (2 * h)
        assert f(x)[1] == pytest.approx(central, rel=1e-5, abs=1e-6), (name, offset)


@pytest.mark.parametrize("name", CASES)
def test_the_documented_error_bound_holds(name):
    _, kink, _ = CASES[name]
    f = ca.Function("f", [xs := ca.SX.sym("x")], [CASES[name][0](xs)])
    x = kink + np.linspace(-60 * EPS, 60 * EPS, 4001)
    error = np.abs(np.asarray(f.map(len(x))(x)).ravel() - SHARP[name](x))
    assert np.isfinite(error).all()
    far = np.abs(x - kink) >= 3 * EPS
    if name == "smooth_sign":
        assert error.max() <= 1.0 + 1e-12 and (error[far] <= 2 * np.exp(-2 * np.abs(x - kink)[far] / EPS) + 1e-15).all()
    elif name == "smooth_sqrt":
        assert error.max() <= ERROR_BOUNDS["smooth_sqrt"] * np.sqrt(EPS)
        rel = error[far] / np.sqrt(np.abs(x[far]))
        assert (rel <= EPS ** 2 / (4 * x[far] ** 2) + 1e-12).all()
    elif name == "smooth_abs":
        assert error.max() <= ERROR_BOUNDS["smooth_abs"] * EPS
    else:
        assert error.max() <= ERROR_BOUNDS["smooth_max"] * EPS + 1e-12
        assert error.max() >= 0.99 * np.log(2) * EPS  # reached at the kink: the bound is tight


def test_far_from_the_kink_nothing_overflows():
    x = ca.SX.sym("x")
    e = ca.vertcat(smooth_max(x, 0.0, EPS), smooth_min(x, 0.0, EPS), smooth_clip(x, -1.0, 1.0, EPS))
    fun = ca.Function("f", [x], [e, ca.jacobian(e, x)])
    for v in (-1e6, 1e6):
        value, slope = (np.asarray(o).ravel() for o in fun(v))
        assert np.isfinite(value).all() and np.isfinite(slope).all()
        np.testing.assert_allclose(value, [max(v, 0.0), min(v, 0.0), np.clip(v, -1, 1)])


def test_a_model_written_with_the_helpers_steps_through_its_kinks():
    """Two tanks connected both ways (the flow reverses) with a saturated pump: RK4 from equal levels, where
    every kink sits, gives finite states and a finite Jacobian equal to central differences."""
    from nnfmu.physics import ModelBuilder

    m = ModelBuilder("connected_tanks", Ts=1.0, n_sub=2)
    h1, h2 = m.state("h1", "m", "left level", scale=0.3), m.state("h2", "m", "right level", scale=0.3)
    u = m.input("u", "V", "pump voltage", min=-2.0, max=12.0)
    k = m.parameter("k", 1e-3, "m2.5/s", "pipe conductance", min=1e-6, max=1.0)
    flow = k * smooth_sqrt(h1 - h2, 1e-3)
    pump = 1e-3 * smooth_clip(u, 0.0, 10.0, 0.05)
    m.ode(h1=pump - flow - 1e-3 * smooth_max(h1 - 0.5, 0.0, 1e-3), h2=flow - 1e-4 * smooth_abs(h2, 1e-3))
    m.output("h2", "m", "right level", h2, start=0.1)
    system = m.build()
    x = ca.SX.sym("x", 2)
    f = ca.Function("f", [x], [system.ode(x, 0.0, system.parameter_values())])
    J = ca.Function("J", [x], [ca.jacobian(system.ode(x, 0.0, system.parameter_values()), x)])
    x0 = np.array([0.2, 0.2])  # equal levels, u = 0: the flow's and the pump's kinks
    jac = np.asarray(J(x0))
    assert np.isfinite(jac).all()
    for j in range(2):
        h = np.eye(2)[j] * 1e-7
        central = (np.asarray(f(x0 + h)) - np.asarray(f(x0 - h))).ravel() / 2e-7
        np.testing.assert_allclose(jac[:, j], central, rtol=1e-5, atol=1e-9)
    from nnfmu.physics import rk4_function

    step = rk4_function(system.ode, Ts=system.Ts, n_sub=system.n_sub, name="step")
    x = x0
    for _ in range(50):
        x = np.asarray(step(x, 0.0, system.parameter_values())).ravel()
        assert np.isfinite(x).all()
    assert np.abs(x - x0).max() < 0.01  # near rest it stays near rest: no kink kicks the states


def test_the_pages_overflow_model_has_an_exact_jacobian_at_its_kinks():
    """docs/own-physics.md's example, run as written: at an empty lower tank, the rim and the pump's saturation,
    CasADi's Jacobian of the ODE equals central differences."""
    import re
    from pathlib import Path

    page = (Path(__file__).resolve().parents[1] / "docs" / "own-physics.md").read_text()
    block = next(b for b in re.findall(r"```python\n(.*?)```", page, flags=re.DOTALL) if "nnfmu.physics.smooth" in b)
    scope: dict = {}
    exec(block, scope)  # noqa: S102 - the page's own example
    system = scope["tanks_overflow"]()
    p = system.parameter_values()
    x, u = ca.SX.sym("x", 2), ca.SX.sym("u")
    f = ca.Function("f", [x, u], [system.ode(x, u, p)])
    J = ca.Function("J", [x, u], [ca.jacobian(system.ode(x, u, p), ca.vertcat(x, u))])
    for x0, u0 in (([0.1, 0.0], 3.0), ([0.3, 0.1], 3.0), ([0.2, 0.1], 8.0)):  # empty tank, at the rim, saturated
        z0 = np.array([*x0, u0])
        jac = np.asarray(J(z0[:2], z0[2]))
        assert np.isfinite(jac).all()
        for j in range(3):
            h = np.eye(3)[j] * 1e-8
            central = (np.asarray(f((z0 + h)[:2], (z0 + h)[2])) - np.asarray(f((z0 - h)[:2], (z0 - h)[2]))).ravel()
            np.testing.assert_allclose(jac[:, j], central / 2e-8, rtol=1e-4, atol=1e-9)
