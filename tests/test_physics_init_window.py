"""The initial state of a physics model from an init window, inside the FMU (issue 34, item 1).

Noise-free data from examples/two_tanks.py (only the lower level measured), the upper tank started away from
its steady state: the FMU with an init window estimates the upper level to within 2 % (it is 1e-9), and its
free run matches the true model's to 1e-6 relative; the FMU equals the CasADi estimator to 1e-9 in float64,
as co-simulation and as Model Exchange; a window of NaN (not set) or huge values gives a finite start and a
run without warnings.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from physics_sim import simulate_states
from test_fmu_model_exchange import MeInstance

from nnfmu.cosim import FmuSimulator, inspect_fmu
from nnfmu.errors import ShapeError
from nnfmu.export import build_fmu
from nnfmu.physics import resolve_physics
from nnfmu.physics.initial_state import compact_step, estimating_model, window_estimator, with_init_window
from nnfmu.window_names import past_element

EXAMPLE = Path(__file__).resolve().parents[1] / "examples" / "two_tanks.py"
WINDOW, START = 30, 60  # the init window (samples) and the sample of t0 in the record


@pytest.fixture(scope="module")
def tanks():
    return resolve_physics(f"{EXAMPLE}:two_tanks")


@pytest.fixture(scope="module")
def record(tanks):
    """(u, x, y): 300 samples of the true model, the upper tank started 40 % above its steady state."""
    rng = np.random.default_rng(0)
    u = np.clip(5 + 3 * np.repeat(rng.standard_normal(15), 20), 0, 10)[:, None]
    p = tanks.parameter_values()
    rest = np.asarray(tanks.init_state(0.08, u[0], p)).ravel()
    x = simulate_states(tanks, [1.4 * rest[0], 0.08], u[:-1])
    y = np.vstack([np.asarray(tanks.output(xk, p)).ravel() for xk in x])
    return u, x, y


@pytest.fixture(scope="module")
def fmu(tanks, tmp_path_factory):
    model = estimating_model(tanks, init_window=WINDOW)
    return model, build_fmu(model, tmp_path_factory.mktemp("tanks") / "tanks_window.fmu")


def _window(u, y, k=START):
    return y[k - WINDOW + 1:k], u[k - WINDOW + 1:k]


def test_the_fmu_estimates_the_upper_level_and_runs_as_the_true_model(tanks, record, fmu):
    u, x, y = record
    model, path = fmu
    y_past, u_past = _window(u, y)
    start = {"h2_start": y[START, 0]}
    start.update({past_element(c, j + 1): v for c, col in (("h2", y_past[:, 0]), ("u", u_past[:, 0]))
                  for j, v in enumerate(col)})
    me = MeInstance(path, start)
    x_fmu = me.states_now()
    rule = np.asarray(tanks.model().init(y[START], u[START], tanks.parameter_values())).ravel()
    assert abs(rule[0] - x[START, 0]) > 0.05 * x[START, 0]  # the init rule alone misses the upper level
    assert abs(x_fmu[0] - x[START, 0]) <= 0.02 * x[START, 0]
    with FmuSimulator(path, ["u"], ["h2"], tanks.Ts) as sim:
        got = sim.simulate(u[START:], y[START], y_past, u_past)
    np.testing.assert_allclose(got, y[START:], rtol=1e-6, atol=0)
    no_window = tanks.model().simulate(u[START:], y[START])
    assert np.abs(no_window - y[START:]).max() > 1e-3 * np.abs(y).max()  # the window is what makes it exact


def test_the_fmu_equals_the_casadi_estimator(tanks, record, fmu):
    u, x, y = record
    model, path = fmu
    p = tanks.parameter_values()
    for k in (WINDOW - 1, START, 200):
        y_past, u_past = _window(u, y, k)
        estimate = window_estimator(tanks.model(), WINDOW, x_scale=tanks.state_scales,
                                    step=compact_step(tanks, tanks.n_sub, expose_parameters=True))
        x_end, x_start, _ = estimate(np.vstack([y_past, y[k:k + 1]]).T, u_past.T, p)
        x0 = model.init(y[k], u[k], p, y_past.ravel(), u_past.ravel())
        np.testing.assert_array_equal(np.asarray(x0).ravel(), np.asarray(x_end).ravel())
        expected = model.simulate(u[k:], y[k], y_past=y_past, u_past=u_past)
        with FmuSimulator(path, ["u"], ["h2"], tanks.Ts) as sim:
            got = sim.simulate(u[k:], y[k], y_past, u_past)
        np.testing.assert_allclose(got / np.abs(expected).max(), expected / np.abs(expected).max(), rtol=0, atol=1e-9)
    info = inspect_fmu(path)
    assert info.init_window == WINDOW and past_element("u", WINDOW - 1) in info.parameters


@pytest.mark.parametrize("bad", [np.nan, 1e200, -1e200])
def test_a_window_of_nan_or_huge_values_gives_a_finite_start_without_warnings(tanks, record, fmu, bad):
    """NaN is "not set" (that sample is y0, or u0: the networks' rule); 1e200 overflows the cost: the init rule."""
    u, x, y = record
    model, path = fmu
    y_past, u_past = _window(u, y)
    y_bad, u_bad = y_past.copy(), u_past.copy()
    y_bad[:5] = bad
    u_bad[3] = bad
    with FmuSimulator(path, ["u"], ["h2"], tanks.Ts) as sim:
        got = sim.simulate(u[START:], y[START], y_bad, u_bad)
        assert not any("warning" in m.lower() or "error" in m.lower() for m in sim.messages), sim.messages
    assert np.isfinite(got).all()
    if np.isnan(bad):
        y_rest, u_rest = y_bad.copy(), u_bad.copy()
        y_rest[:5], u_rest[3] = y[START], u[START]
        expected = model.simulate(u[START:], y[START], y_past=y_rest, u_past=u_rest)
    else:
        expected = tanks.model().simulate(u[START:], y[START])  # the init rule
    np.testing.assert_allclose(got, expected, rtol=1e-9, atol=1e-12)


def test_the_compact_step_is_the_models_step(tanks, record):
    u, x, _ = record
    p = tanks.parameter_values()
    for expose in (True, False):
        step, compact = tanks.model(expose_parameters=expose).step, compact_step(tanks, 2, expose_parameters=expose)
        for k in (0, 100, 250):
            args = [x[k], u[k]] + [p] * expose
            for a, b in zip(step(*args), compact(*args)):
                np.testing.assert_allclose(np.asarray(b).ravel(), np.asarray(a).ravel(), rtol=1e-14, atol=0)


def test_with_init_window_checks_its_arguments(tanks):
    model = tanks.model()
    assert with_init_window(model, 1) is model
    with pytest.raises(ShapeError, match="init window must be a whole number"):
        with_init_window(model, 0)
    with pytest.raises(ShapeError, match="already has an init window"):
        with_init_window(with_init_window(model, 5), 5)
    with pytest.raises(ShapeError, match="positive numbers"):
        with_init_window(model, 5, y_scale=[0.0])


class _ArraysMe(MeInstance):
    """FMI 3 Model Exchange whose start values may be arrays (their values follow the references in order)."""

    def set(self, values: dict) -> None:
        self.fmu.setFloat64([self.vr[k] for k in values], [float(v) for a in values.values() for v in np.ravel(a)])


def test_fmi3_arrays_and_model_exchange_take_the_window(tanks, record, tmp_path):
    """FMI 3: one array ``<c>_past`` per channel; the FMU validates (its ModelStructure names the window)."""
    from fmpy.validation import validate_fmu

    u, x, y = record
    model = estimating_model(tanks, init_window=WINDOW)
    path = build_fmu(model, tmp_path / "tanks3.fmu", fmi_version=3)
    assert validate_fmu(str(path)) == []
    y_past, u_past = _window(u, y)
    me = _ArraysMe(path, {"h2_start": y[START, 0], "h2_past": y_past[:, 0], "u_past": u_past[:, 0]})
    x0 = model.init(y[START], u[START], tanks.parameter_values(), y_past.ravel(), u_past.ravel())
    np.testing.assert_allclose(me.states_now(), np.asarray(x0).ravel(), rtol=1e-12, atol=0)
    with FmuSimulator(path, ["u"], ["h2"], tanks.Ts) as sim:
        got = sim.simulate(u[START:], y[START], y_past, u_past)
    np.testing.assert_allclose(got, y[START:], rtol=1e-6, atol=0)


def test_an_infinite_window_value_is_the_networks_error(tanks, record, fmu):
    """As a network's init window: an infinite sample is an error at initialisation that names it."""
    u, x, y = record
    _, path = fmu
    y_past, u_past = _window(u, y)
    bad = y_past.copy()
    bad[2, 0] = np.inf
    with FmuSimulator(path, ["u"], ["h2"], tanks.Ts) as sim:
        with pytest.raises(Exception, match="sample 3 .* h2_past is inf"):
            sim.simulate(u[START:], y[START], bad, u_past)
