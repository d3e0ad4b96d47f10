"""The fixed-step RK4 discretisation and the (init, step) models built from it."""

from __future__ import annotations

import casadi as ca
import numpy as np
import pytest
import scipy.linalg

from nnfmu.errors import ConfigError
from nnfmu.physics import PhysicsSystem, compile_function, rk4_function, rk4_step, valve_system
from nnfmu.system import Variable


def _oscillator() -> ca.Function:
    """Damped oscillator ``x1' = x2, x2' = -w^2 x1 - 2 z w x2 + u`` with p = [w, z]."""
    x, u, p = ca.SX.sym("x", 2), ca.SX.sym("u", 1), ca.SX.sym("p", 2)
    xdot = ca.vertcat(x[1], -p[0] ** 2 * x[0] - 2 * p[1] * p[0] * x[1] + u)
    return ca.Function("osc", [x, u, p], [xdot], ["x", "u", "p"], ["xdot"])


def _exact(x0, u, p, T):
    """Exact solution of the linear oscillator with constant input (matrix exponential)."""
    w, z = p
    aug = np.array([[0, 1, 0], [-w**2, -2 * z * w, u], [0, 0, 0]], dtype=float)
    return (scipy.linalg.expm(aug * T) @ np.array([*x0, 1.0]))[:2]


def test_rk4_converges_with_order_four():
    ode, x0, u, p, T = _oscillator(), np.array([1.0, 0.0]), 0.7, np.array([3.0, 0.1]), 1.0
    n_subs = np.array([4, 8, 16, 32])
    errors = [np.linalg.norm(np.asarray(rk4_step(ode, ca.DM(x0), u, ca.DM(p), Ts=T, n_sub=n)).ravel()
                             - _exact(x0, u, p, T)) for n in n_subs]
    orders = np.diff(np.log(errors)) / np.diff(np.log(1.0 / n_subs))
    assert np.all((orders > 3.8) & (orders < 4.2)), orders


def test_rk4_accepts_plain_python_callables():
    # A hybrid model passes its own rhs (physics plus a correction); numpy values work too.
    x_next = rk4_step(lambda x, u, p: -p * x + u, np.array([1.0]), 0.0, 2.0, Ts=0.5, n_sub=200)
    assert x_next[0] == pytest.approx(np.exp(-1.0), rel=1e-10)


def test_unrolled_and_folded_rk4_agree():
    ode = _oscillator()
    unrolled = rk4_function(ode, Ts=0.3, n_sub=12, unroll_max=16)
    folded = rk4_function(ode, Ts=0.3, n_sub=12, unroll_max=8)
    assert unrolled.is_a("SXFunction") and not folded.is_a("SXFunction")
    args = ([0.3, -1.2], 0.4, [2.5, 0.2])
    assert np.allclose(np.asarray(unrolled(*args)), np.asarray(folded(*args)), rtol=1e-13, atol=1e-15)
    assert folded.name_in() == ["x", "u", "p"] and folded.name_out() == ["x_next"]


@pytest.mark.parametrize("n_sub", [0, -2, 1.5])
def test_bad_substep_count_is_rejected(n_sub):
    with pytest.raises(ConfigError, match="n_sub must be a positive integer"):
        rk4_function(_oscillator(), Ts=0.1, n_sub=n_sub)


def _oscillator_system() -> PhysicsSystem:
    ode = _oscillator()
    x, p, y0, u = ca.SX.sym("x", 2), ca.SX.sym("p", 2), ca.SX.sym("y0", 1), ca.SX.sym("u", 1)
    return PhysicsSystem(
        name="osc", Ts=0.05, n_sub=3, ode=ode,
        output=ca.Function("out", [x, p], [x[0]], ["x", "p"], ["y"]),
        init_state=ca.Function("init", [y0, u, p], [ca.vertcat(y0, 0)], ["y0", "u0", "p"], ["x0"]),
        states=(Variable("pos", "m"), Variable("vel", "m/s")), inputs=(Variable("f", "N"),),
        outputs=(Variable("y", "m"),), parameters=(Variable("w", "rad/s", start=3.0), Variable("z", start=0.1)))


def test_model_follows_the_dataset_convention():
    system = _oscillator_system()
    model = system.model()
    u = np.sin(np.arange(40) * 0.3)[:, None]
    y = model.simulate(u, [0.5])
    x = np.array([0.5, 0.0])
    for k in range(39):  # y[k+1] from x after u[k] acted for one Ts
        x = np.asarray(rk4_step(system.ode, ca.DM(x), u[k], ca.DM([3.0, 0.1]), Ts=0.05, n_sub=3)).ravel()
        assert y[k + 1, 0] == pytest.approx(x[0], rel=1e-12, abs=1e-15)
    assert y[0, 0] == 0.5


def test_baked_parameters_equal_exposed_nominal_parameters():
    system = valve_system()
    exposed, baked = system.model(), system.model(expose_parameters=False)
    assert exposed.step.name_in() == ["x", "u", "p"] and baked.step.name_in() == ["x", "u"]
    assert [v.name for v in exposed.spec.parameters] == [v.name for v in system.parameters]
    assert baked.spec.parameters == ()
    x0 = np.asarray(system.init_state([0.4e-3, 3e5], [120, 80], system.parameter_values())).ravel()
    a = exposed.step(x0, [150, 60], system.parameter_values())
    b = baked.step(x0, [150, 60])
    for got, want in zip(b, a):
        assert np.allclose(np.asarray(got), np.asarray(want), rtol=1e-14, atol=0)


def test_valve_step_generates_c_that_reproduces_it():
    model = valve_system().model()
    compiled = compile_function(model.step)
    assert compiled.is_a("External")
    rng = np.random.default_rng(1)
    p = valve_system().parameter_values()
    for _ in range(5):
        x = np.array([rng.uniform(0, 1e-4), 0.0, rng.uniform(0, 1e-4), 0.0, rng.uniform(1.1e5, 6.9e5),
                      rng.uniform(0, 1e-3), rng.normal(0, 0.1)])
        u = rng.uniform(0, 250, 2)
        for got, want in zip(compiled(x, u, p), model.step(x, u, p)):
            assert np.allclose(np.asarray(got), np.asarray(want), rtol=1e-13, atol=0)


def test_compiled_functions_are_cached_atomically(tmp_path, monkeypatch):
    monkeypatch.setenv("NNFMU_CACHE_DIR", str(tmp_path))
    step = rk4_function(_oscillator(), Ts=0.1, n_sub=2, name="osc_rk4")
    first = compile_function(step)
    libraries = list((tmp_path / "compiled").iterdir())
    assert [f.suffix for f in libraries] == [".so"]  # no temporary file left behind
    stamp = libraries[0].stat().st_mtime_ns
    second = compile_function(step)  # same code: loaded from the cache, not rebuilt
    assert libraries[0].stat().st_mtime_ns == stamp
    assert np.array_equal(np.asarray(first([1, 2], 3, [2, 0.5])), np.asarray(second([1, 2], 3, [2, 0.5])))
    assert np.allclose(np.asarray(first([1, 2], 3, [2, 0.5])), np.asarray(step([1, 2], 3, [2, 0.5])), rtol=1e-14)
