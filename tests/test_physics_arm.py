"""The KR300 arm: RNEA, mass matrix and forward dynamics against physics.md's reference values."""

from __future__ import annotations

import dataclasses
import math

import casadi as ca
import numpy as np
import pytest

from nnfmu.data.loaders import ROBOT_INPUTS, ROBOT_OUTPUTS
from nnfmu.physics import ArmParams, arm_system, bias_torque, kinetic_energy, mass_matrix, rnea
from nnfmu.physics.arm import THETA_OFFSET, arm_friction, arm_links, counterbalance_torque
from nnfmu.physics.base import parameter_variables, unpack_parameters
from physics_sim import simulate_states

GRAVITY_REF = np.array([0.0, -2834.2, -2837.5, -25.04, -536.23, 0.0])      # N m at q = 0 (q_DH = [0,-90,90,0,0,0])
DIAG_M_REF = np.array([1300.5, 1779.8, 1110.3, 85.17, 117.19, 41.20])      # kg m^2, rotors included
BASE_ACC = ca.DM([0, 0, -9.81])  # R_base^T [0, 0, g], R_base = rotx(180 deg)


def _numeric_links(params: ArmParams = ArmParams()):
    values = ca.DM([v.start for v in parameter_variables(params)])
    return arm_links(unpack_parameters(params, values))


def _theta(q):
    return ca.DM(q) + ca.DM(THETA_OFFSET)


def _random_states(n, seed=0):
    rng = np.random.default_rng(seed)
    return [(rng.uniform(-1.5, 1.5, 6), rng.normal(0, 0.5, 6), rng.normal(0, 1.0, 6)) for _ in range(n)]


def test_gravity_torque_at_the_reference_pose():
    g = np.asarray(ca.evalf(rnea(_numeric_links(), _theta(np.zeros(6)), np.zeros(6), np.zeros(6), BASE_ACC)))
    g = g.ravel()
    big = np.abs(GRAVITY_REF) > 1
    assert np.allclose(g[big], GRAVITY_REF[big], rtol=1e-3, atol=0)
    assert np.abs(g[~big]).max() < 1e-3 * np.abs(GRAVITY_REF).max()


def test_mass_matrix_diagonal_at_the_reference_pose():
    M = np.asarray(ca.evalf(mass_matrix(_numeric_links(), _theta(np.zeros(6)))))
    assert np.allclose(np.diag(M), DIAG_M_REF, rtol=1e-3, atol=0)
    params = ArmParams()
    rotor = np.array(params.gear) ** 2 * np.array(params.J_m)
    assert np.allclose(rotor, [609, 844, 751, 84.5, 99.3, 41.2], rtol=2e-3)


@pytest.mark.parametrize("q, qd, qdd", _random_states(4))
def test_mass_matrix_is_symmetric_positive_definite(q, qd, qdd):
    M = np.asarray(ca.evalf(mass_matrix(_numeric_links(), _theta(q))))
    assert np.abs(M - M.T).max() < 1e-10 * np.abs(M).max()  # built column by column from RNEA, not symmetrised
    assert np.linalg.eigvalsh(M).min() > 1.0


@pytest.mark.parametrize("q, qd, qdd", _random_states(4, seed=1))
def test_rnea_equals_mass_matrix_times_acceleration_plus_bias(q, qd, qdd):
    links, theta = _numeric_links(), _theta(q)
    tau = np.asarray(ca.evalf(rnea(links, theta, qd, qdd, BASE_ACC))).ravel()
    M = np.asarray(ca.evalf(mass_matrix(links, theta)))
    h = np.asarray(ca.evalf(bias_torque(links, theta, qd, BASE_ACC))).ravel()
    assert np.allclose(tau, M @ qdd + h, rtol=1e-10, atol=1e-8)


def test_forward_dynamics_inverts_the_inverse_dynamics():
    """ode's qdd fed back through RNEA + friction + counterbalance gives back G * tau_motor."""
    params, system = ArmParams(), arm_system(f_b_cap=None)
    links = _numeric_links(params)
    P = unpack_parameters(params, ca.DM(system.parameter_values()))
    for q, qd, _ in _random_states(3, seed=2):
        tau_m = np.random.default_rng(3).normal(0, 5, 6)
        qdd = np.asarray(system.ode(np.concatenate([q, qd]), tau_m, system.parameter_values())).ravel()[6:]
        load = arm_friction(ca.DM(qd), P) + ca.vertcat(0, counterbalance_torque(q[1] - math.pi / 2, P), 0, 0, 0, 0)
        tau_link = np.asarray(ca.evalf(rnea(links, _theta(q), qd, qdd, BASE_ACC) + load)).ravel()
        assert np.allclose(tau_link, np.array(params.gear) * tau_m, rtol=1e-9, atol=1e-6)


def test_energy_is_conserved_without_friction_gravity_and_torque():
    zeros = (0.0,) * 6
    params = dataclasses.replace(ArmParams(), g=0.0, cb_m=0.0, f_vis=zeros, f_coul=zeros, f_a=zeros, f_asym=zeros)
    system = arm_system(params)
    x0 = np.concatenate([[0.3, -0.2, 0.4, 1.0, -0.5, 0.7], [0.4, -0.3, 0.5, 1.5, -1.0, 2.0]])
    xs = simulate_states(system, x0, np.zeros((20, 6)), n_sub=20)  # 2 s with h = 5 ms
    energy = ca.Function("E", [q := ca.SX.sym("q", 6), qd := ca.SX.sym("qd", 6)],
                         [kinetic_energy(_numeric_links(params), q + ca.DM(THETA_OFFSET), qd)])
    e = np.array([float(energy(x[:6], x[6:])) for x in xs])
    assert np.ptp(xs[:, 0]) > 0.1  # it really moved
    assert np.abs(e - e[0]).max() < 1e-6 * e[0]


def test_counterbalance_is_neutral_near_vertical_and_helps_gravity_at_the_reference_pose():
    P = unpack_parameters(ArmParams(), ca.DM([v.start for v in parameter_variables(ArmParams())]))
    assert abs(float(counterbalance_torque(math.radians(-95.0), P))) < 1e-9
    tau_cb = float(counterbalance_torque(math.radians(-90.0), P))
    # the joint must hold g + tau_cb: the counterbalance carries part of the gravity load
    assert abs(GRAVITY_REF[1] + tau_cb) < abs(GRAVITY_REF[1])
    assert 500 < tau_cb < 800


def test_the_model_holds_still_under_its_static_holding_torque():
    """Motor torques (g + tau_cb + f_asym) / G keep the RK4 model at rest for 5 s (signs end to end)."""
    system, params = arm_system(), ArmParams()
    P = unpack_parameters(params, ca.DM(system.parameter_values()[:-1]))
    q = np.array([0.2, 0.1, -0.3, 0.5, 0.4, -0.2])
    g = rnea(_numeric_links(params), _theta(q), np.zeros(6), np.zeros(6), BASE_ACC)
    hold = g + ca.vertcat(0, counterbalance_torque(q[1] - math.pi / 2, P), 0, 0, 0, 0) + ca.DM(params.f_asym)
    tau_m = np.asarray(ca.evalf(hold)).ravel() / np.array(params.gear)
    y = system.model().simulate(np.tile(tau_m, (50, 1)), np.degrees(q))
    assert np.abs(y - np.degrees(q)).max() < 1e-6


def test_channels_match_the_robot_benchmark():
    system = arm_system()
    assert [(v.name, v.unit) for v in system.inputs] == [(c.name, c.unit) for c in ROBOT_INPUTS]
    assert [(v.name, v.unit) for v in system.outputs] == [(c.name, c.unit) for c in ROBOT_OUTPUTS]
    assert system.Ts == 0.1
    names = [v.name for v in system.parameters]
    assert len(set(names)) == len(names) and names[-1] == "f_b_cap"
    assert "f_b_cap" not in [v.name for v in arm_system(f_b_cap=None).parameters]
    x0 = np.asarray(system.init_state(np.arange(6.0), np.zeros(6), system.parameter_values())).ravel()
    assert np.allclose(x0, np.concatenate([np.radians(np.arange(6.0)), np.zeros(6)]))


def _cvodes_run(system, x0, torques):
    """Reference free run with CVODES (BDF), zero-order hold on the torques; angles in deg."""
    x, u = ca.SX.sym("x", 12), ca.SX.sym("u", 6)
    p = ca.SX.sym("p", len(system.parameters))
    dae = {"x": x, "p": ca.vertcat(u, p), "ode": system.ode(x, u, p)}
    step = ca.integrator("F", "cvodes", dae, 0.0, [system.Ts], {"abstol": 1e-10, "reltol": 1e-10})
    xs, pv = [np.asarray(x0, float)], system.parameter_values()
    for tau in torques[:-1]:
        xs.append(np.asarray(step(x0=xs[-1], p=np.concatenate([tau, pv]))["xf"]).ravel())
    return np.degrees(np.array(xs)[:, :6])


def test_default_rk4_model_stays_close_to_the_exact_stiff_model():
    """The stiction-slope cap (ARM_F_B_CAP) and RK4 (ARM_N_SUB) against CVODES on the identified model.

    Open loop, 4 s of torques around the static holding torque with velocity reversals.
    """
    params, capped, exact = ArmParams(), arm_system(), arm_system(f_b_cap=None)
    q0 = np.array([0.2, 0.1, -0.3, 0.5, 0.4, -0.2])
    P = unpack_parameters(params, ca.DM(exact.parameter_values()))
    g = rnea(_numeric_links(params), _theta(q0), np.zeros(6), np.zeros(6), BASE_ACC)
    hold = np.asarray(ca.evalf(g + ca.vertcat(0, counterbalance_torque(q0[1] - math.pi / 2, P), 0, 0, 0, 0)))
    t = np.arange(40)[:, None] * 0.1
    amplitude = np.array([3.0, 3.0, 3.0, 0.8, 0.8, 0.8])  # N m, about the real data's spread
    torques = hold.ravel() / np.array(params.gear) + amplitude * np.sin(2 * np.pi * t / 2.0 + np.arange(6))
    y_rk4 = capped.model().simulate(torques, np.degrees(q0))
    y_capped = _cvodes_run(capped, np.concatenate([q0, np.zeros(6)]), torques)
    y_exact = _cvodes_run(exact, np.concatenate([q0, np.zeros(6)]), torques)
    assert np.ptp(y_exact, axis=0).min() > 1.0  # every joint moves by more than a degree
    assert np.abs(y_rk4 - y_capped).max() < 0.01   # RK4 with 50 sub-steps: discretisation error
    assert np.abs(y_rk4 - y_exact).max() < 0.2     # the cap's effect over 4 s open loop (measured 0.07 deg)


def test_friction_and_masses_cannot_go_negative_in_a_fit():
    """A fit of the robot left free put two viscous frictions below zero and every free run diverged: the arm
    declares friction, masses and inertias of the rotors non-negative, and the grey-box fit keeps them so."""
    from nnfmu.greybox.setup import choose_unknowns

    system = arm_system()
    bounded = {v.name: v.min for v in system.parameters if v.min is not None}
    for name in ("f_vis", "f_coul", "f_a", "f_b", "m", "J_m"):
        assert all(bounded.get(f"{name}{j}") == 0.0 for j in range(1, 7)), name
    assert "f_asym1" not in bounded and "rcx1" not in bounded  # offsets and positions keep their sign free
    unknowns = choose_unknowns(system, free=["f_vis4", "f_asym4"])
    assert unknowns.lower.tolist() == [0.0, -math.inf]
