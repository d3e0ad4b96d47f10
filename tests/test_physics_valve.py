"""The pneumatic valve model against the behaviour physics.md lists for its parameter set.

Tolerances: rise time within 20 % of "about 5 ms"; equilibrium pressure with
both pilots at 120 V within 0.05 bar of 5.45 bar; static plunger positions
within 5 um of the force balance (the smoothed Coulomb friction leaves at most
F_C / k_s = 20 um, in practice about 1 um after 80 ms); RK4 with 4 sub-steps
within 4 Pa and 0.02 um of 40 sub-steps (physics.md's figures).
"""

from __future__ import annotations

import dataclasses

import casadi as ca
import numpy as np
import pytest

from nnfmu.physics import ValveParams, valve_system
from physics_sim import simulate_states

TS = 40e-6
P_A = 1.013e5


@pytest.fixture(scope="module")
def valve():
    return valve_system()


@pytest.fixture(scope="module")
def rest_state(valve):
    """Both pilots closed, plunger settled on its seat, chamber at ambient pressure."""
    x0 = np.asarray(valve.init_state([0.0, P_A], [0.0, 0.0], valve.parameter_values())).ravel()
    return simulate_states(valve, x0, np.zeros((500, 2)))[-1]


def _hold(valve, x0, u1, u2, n):
    return simulate_states(valve, x0, np.tile([u1, u2], (n, 1)))


def test_variables_are_named_with_units(valve):
    assert [v.name for v in valve.states] == ["z1", "z1dot", "z2", "z2dot", "p", "s", "sdot"]
    assert [(v.name, v.unit) for v in valve.inputs] == [("u1", "V"), ("u2", "V")]
    assert [(v.name, v.unit) for v in valve.outputs] == [("s", "m"), ("p", "Pa")]
    assert valve.Ts == TS and valve.n_sub == 4
    by_name = {v.name: v for v in valve.parameters}
    assert by_name["C_max"].unit == "m3/(s.Pa)" and by_name["C_max"].start == 6e-10
    assert by_name["k_c"].start == 5e6 and by_name["d_c"].unit == "N.s/m"
    assert len(by_name) == len(valve.parameters)


def test_rest_state_is_closed_at_ambient_pressure(rest_state):
    assert rest_state[4] == pytest.approx(P_A, rel=1e-3)
    assert -5e-6 < rest_state[5] < 0.0  # pressed a little into the seat by the spring preload


def test_pressure_rise_time_with_the_inlet_fully_open(valve, rest_state):
    xs = _hold(valve, rest_state, 250.0, 0.0, 1000)
    p = xs[:, 4]
    assert p[-1] == pytest.approx(7.0e5, rel=1e-3)
    t90 = np.argmax(p >= p[0] + 0.9 * (p[-1] - p[0])) * TS
    assert 4e-3 <= t90 <= 6e-3, t90


def test_both_pilots_at_120_volts_settle_near_5_45_bar(valve, rest_state):
    xs = _hold(valve, rest_state, 120.0, 120.0, 3000)
    assert np.ptp(xs[-250:, 4]) < 10.0  # settled
    assert xs[-1, 4] == pytest.approx(5.45e5, abs=0.05e5)


@pytest.mark.parametrize("u1, u2", [(80, 150), (100, 200), (120, 200), (120, 160), (150, 230)])
def test_plunger_travels_from_2_0_to_5_2_bar(valve, rest_state, u1, u2):
    """Static equilibria lie on the spring line: s = 0 at 2.03 bar, s = 1 mm at 5.22 bar."""
    xs = _hold(valve, rest_state, u1, u2, 2000)
    p, s = xs[-1, 4], xs[-1, 5]
    params = ValveParams()
    p_lift = params.p_a + params.F0 / params.A_p
    p_full = params.p_a + (params.F0 + params.k_s * params.s_max) / params.A_p
    assert p_lift == pytest.approx(2.03e5, abs=0.01e5) and p_full == pytest.approx(5.22e5, abs=0.01e5)
    assert p_lift < p < p_full  # these voltages give intermediate pressures
    assert s == pytest.approx(params.s_max * (p - p_lift) / (p_full - p_lift), abs=5e-6)


def test_end_stops_hold_the_plunger_inside_its_stroke(valve, rest_state):
    open_ = _hold(valve, rest_state, 250.0, 0.0, 1500)
    closed = _hold(valve, open_[-1], 0.0, 250.0, 1500)
    assert open_[:, 5].max() < 1.01e-3 and open_[-1, 5] > 0.995e-3
    assert closed[:, 5].min() > -10e-6 and closed[-1, 5] < 5e-6


def test_rk4_with_four_substeps_matches_forty(valve, rest_state):
    rng = np.random.default_rng(0)
    u = np.repeat(rng.uniform(0, 250, (12, 2)), 250, axis=0)  # steps with contacts at both ends
    ref = simulate_states(valve, rest_state, u, n_sub=40)
    got = simulate_states(valve, rest_state, u, n_sub=4)
    assert ref[:, 5].max() > 0.99e-3 and ref[:, 5].min() < 0.01e-3
    assert np.abs(got[:, 4] - ref[:, 4]).max() < 4.0
    assert np.abs(got[:, 5] - ref[:, 5]).max() < 0.02e-6


def test_init_state_puts_benders_at_rest_at_their_static_deflection(valve):
    p = valve.parameter_values()
    x0 = np.asarray(valve.init_state([0.3e-3, 3.1e5], [100.0, 200.0], p)).ravel()
    assert np.allclose(x0, [40e-6, 0, 80e-6, 0, 3.1e5, 0.3e-3, 0], rtol=1e-12, atol=0)
    xdot = np.asarray(valve.ode(x0, [100.0, 200.0], p)).ravel()
    assert np.allclose(xdot[:4], 0.0, atol=1e-12)
    assert np.asarray(valve.output(x0, p)).ravel() == pytest.approx([0.3e-3, 3.1e5])


def test_mis_specified_variant_comes_through_the_parameter_port(valve):
    """'Spring and orifice 30 % off, no end-stop damping': the same ODE with other p values."""
    nominal = ValveParams()
    variant = dataclasses.replace(nominal, k_s=1.3 * nominal.k_s, C_max=0.7 * nominal.C_max, d_c=0.0)
    other = valve_system(variant)
    p_variant = other.parameter_values()
    assert p_variant[[v.name for v in other.parameters].index("d_c")] == 0.0
    rng = np.random.default_rng(2)
    for _ in range(5):
        x = [rng.uniform(0, 1e-4), 0.1, rng.uniform(0, 1e-4), -0.1, rng.uniform(1.2e5, 6e5),
             rng.uniform(-2e-6, 1.002e-3), rng.normal(0, 0.2)]
        u = rng.uniform(0, 250, 2)
        same = np.asarray(valve.ode(x, u, p_variant)), np.asarray(other.ode(x, u, p_variant))
        assert np.array_equal(*same)
        assert not np.allclose(np.asarray(valve.ode(x, u, valve.parameter_values())), same[0])


def test_ode_is_a_code_generable_sx_function(valve):
    assert valve.ode.is_a("SXFunction")
    assert valve.ode.name_in() == ["x", "u", "p"] and valve.ode.name_out() == ["xdot"]
    assert not valve.ode.has_free()
    # Every parameter really enters the ODE (no hidden constant instead of a port entry).
    xdot = valve.ode(ca.SX.sym("x", 7), ca.SX.sym("u", 2), p := ca.SX.sym("p", len(valve.parameters)))
    unused = [v.name for i, v in enumerate(valve.parameters) if not ca.depends_on(xdot, p[i])]
    assert unused == []
