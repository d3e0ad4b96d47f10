"""KUKA KR300 R2500 ultra SE: 6-DOF rigid arm with friction and hydraulic counterbalance (physics.md section 3).

States ``x = [q1..q6, qd1..qd6]`` (rad, rad/s) in the benchmark's joint convention;
inputs ``tau1..tau6``: motor torques (N m, motor side); outputs ``q1..q6`` in
degrees, the channels of :data:`nnfmu.data.loaders.ROBOT_INPUTS` / ``ROBOT_OUTPUTS``,
so that this model can be scored on the real benchmark data; Ts = 0.1 s.

Angle conventions (verified against physics.md's reference values):

- benchmark/measured ``q`` -> ``q_DH = q + [0, -pi/2, pi/2, 0, 0, 0]`` (the KUKA
  axis angles; the joint limits of :data:`ARM_Q_LIMITS_DEG` refer to these);
- the DH transform of joint 3 adds its offset of +pi/2, so the angle inside
  the DH transforms is ``theta = q + [0, -pi/2, pi, 0, 0, 0]``;
- reference pose ``q = 0`` (``q_DH = [0, -90, 90, 0, 0, 0]`` deg).

Equation of motion (link side, ``G`` the gear ratios)::

    M(q) qdd + h(q, qd) + tau_f(qd) + tau_cb(q) = G * tau_motor

with ``M`` including the reflected rotor inertia ``G^2 J_m``, the identified
friction ``tau_f = f_asym + f_vis qd + f_coul tanh(qd) + f_a tanh(f_b qd)`` and
the counterbalance torque ``tau_cb`` on joint 2.

Stiffness. The identified stiction slopes ``f_b`` (up to 47 299 s/rad) make
the ODE very stiff near zero joint velocity: the friction Jacobian reaches
``f_a f_b / M_jj``, about 8e3 1/s, which explicit RK4 at Ts = 0.1 s could
only follow with about 300 sub-steps per sample. :func:`arm_system` therefore
caps the slope used in the ODE, ``f_b_eff = min(f_b, f_b_cap)``, with
``f_b_cap`` = :data:`ARM_F_B_CAP` = 500 s/rad by default, exposed as the last
parameter ``f_b_cap`` (tunable and fittable like the others). The largest
Jacobian eigenvalue is then about ``2 f_b_cap`` = 1e3 1/s (joint 6), and
:data:`ARM_N_SUB` = 50 sub-steps (h = 2 ms, ``h |lambda| = 2``) keep RK4
stable. ``f_b_cap=None`` gives the exact identified model, which the data
generator integrates with CVODES (BDF).

Measured effect (open loop, driven by recorded torques, against CVODES on the
exact model): 0.07 deg after 4 s around a static pose
(tests/test_physics_arm.py); at most 0.1 / 1.1 / 1.8 / 0.3 / 3.0 / 0.04 deg
(joints 1..6) over 5 s windows of a closed-loop record, where the exact
model's own mismatch to the record (zero-order hold of the torque) is up to
2.3 deg. RK4 with 50 sub-steps adds less than 0.002 deg. A 3600-sample record
takes about 1.5 s as compiled C. Open loop, any rigid model (exact or capped)
drifts away within 10-20 s: the benchmark's known difficulty.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import casadi as ca

from nnfmu.data.loaders import ROBOT_INPUTS, ROBOT_OUTPUTS
from nnfmu.physics.arm_dynamics import Link, forward_dynamics
from nnfmu.physics.base import PhysicsSystem, param, params_to_json
from nnfmu.physics.builder import ModelBuilder

__all__ = ["ArmParams", "arm_system", "arm_links", "arm_friction", "counterbalance_torque",
           "ARM_TS", "ARM_F_B_CAP", "ARM_N_SUB", "ARM_Q_LIMITS_DEG", "ARM_TAU_LIMITS_NM", "Q_DH_OFFSET",
           "THETA_OFFSET"]

ARM_TS = 0.1
ARM_F_B_CAP = 500.0  # s/rad: stiction slope used by the RK4 model (see the module docstring)
ARM_N_SUB = 50       # RK4 sub-steps per 0.1 s (h = 2 ms): h * |lambda_max| = 2 with the cap
Q_DH_OFFSET = (0.0, -math.pi / 2, math.pi / 2, 0.0, 0.0, 0.0)
THETA_OFFSET = (0.0, -math.pi / 2, math.pi, 0.0, 0.0, 0.0)
# Joint limits in degrees of q_DH (the KUKA axis angles), physics.md's table.
ARM_Q_LIMITS_DEG = ((-147.0, 147.0), (-140.0, -5.0), (-112.0, 153.0),
                    (-350.0, 350.0), (-122.5, 122.5), (-350.0, 350.0))
# Motor torque limits in N m: the inputs' valid range, declared as min/max by an FMU of the model. An
# assumption (the KR300's motor data are not public): about twice the largest torque per axis in the
# benchmark's records (8.8, 15.3, 19.9, 3.4, 4.7, 2.8 N m), rounded up.
ARM_TAU_LIMITS_NM = ((-20.0, 20.0), (-35.0, 35.0), (-40.0, 40.0), (-8.0, 8.0), (-10.0, 10.0), (-6.0, 6.0))

_J6 = tuple(range(6))


@dataclass(frozen=True, kw_only=True)
class ArmParams:
    """Parameters of the KR300 model (physics.md section 3); ``dataclasses.replace`` makes variants.

    DH geometry and gear ratios are structural constants (not tunable); every
    other field goes through the ``p`` port. Link 6's centre of mass ``rcz6``
    is that of the bare flange (-0.05 m); the payload is a point mass
    ``m_payload`` at ``r_payload`` on the z6 axis, lumped into link 6's mass
    and centre of mass as in the identified model (no extra inertia).
    """

    d: tuple = param((-0.675, -0.189, 0.189, -1.0, 0.0, -0.24), "m", "DH offset d", tunable=False)
    a: tuple = param((0.350, 1.150, 0.041, 0.0, 0.0, 0.0), "m", "DH length a", tunable=False)
    alpha: tuple = param((math.pi / 2, 0.0, -math.pi / 2, math.pi / 2, -math.pi / 2, math.pi), "rad",
                         "DH twist alpha", tunable=False)
    gear: tuple = param((1798 / 7, 1872 / 7, 757 / 3, 221.0, 5032 / 21, 206793 / 1340), "1",
                        "gear ratio (motor turns per joint turn)", tunable=False)
    m: tuple = param((395.40, 339.12, 105.21, 35.80, 31.46, 17.78), "kg", "link mass", min=0.0)
    rcx: tuple = param((-0.353, -0.709, -0.018, 0.0, 0.0, 0.0), "m", "centre of mass x in the link frame")
    rcy: tuple = param((0.174, -0.001, -0.018, 0.236, -0.080, 0.0), "m", "centre of mass y in the link frame")
    rcz: tuple = param((-0.004, 0.023, -0.076, 0.001, -0.009, -0.05), "m", "centre of mass z in the link frame")
    Ixx: tuple = param((16.734, 7.508, 10.784, 0.4250, 0.2838, 0.0), "kg.m2", "inertia xx about the centre of mass")
    Iyy: tuple = param((29.799, 88.887, 10.186, 0.2180, 0.2296, 0.0), "kg.m2", "inertia yy about the centre of mass")
    Izz: tuple = param((32.815, 88.674, 1.943, 0.4285, 0.2583, 0.0), "kg.m2", "inertia zz about the centre of mass")
    Ixy: tuple = param((-1.704, 0.430, 0.118, 0.0, 0.0, 0.0), "kg.m2", "inertia xy about the centre of mass")
    Iyz: tuple = param((0.129, 0.173, -0.606, -0.0114, -0.0195, 0.0), "kg.m2", "inertia yz about the centre of mass")
    Ixz: tuple = param((4.404, -4.397, -0.102, 0.0, -0.0001, 0.0), "kg.m2", "inertia xz about the centre of mass")
    J_m: tuple = param((0.00923, 0.0118, 0.0118, 0.00173, 0.00173, 0.00173), "kg.m2", "motor rotor inertia", min=0.0)
    m_payload: float = param(150.0, "kg", "payload mass (point mass on the z6 axis)", min=0.0)
    r_payload: float = param(0.1, "m", "payload position on the z6 axis in frame 6")
    g: float = param(9.81, "m/s2", "gravitational acceleration")
    f_vis: tuple = param((1939.5, 1729.9, 1562.4, 280.5, 468.1, 384.4), "N.m.s/rad", "viscous friction", min=0.0)
    f_coul: tuple = param((31.65, 117.46, 85.65, 49.74, 111.06, 5.29), "N.m", "Coulomb friction (tanh(qd))", min=0.0)
    f_a: tuple = param((318.6, 420.7, 291.5, 43.9, 13.8, 82.4), "N.m", "stiction amplitude", min=0.0)
    f_b: tuple = param((1146.0, 47299.0, 10086.0, 3784.0, 4043.0, 3966.0), "s/rad", "stiction slope", min=0.0)
    f_asym: tuple = param((4.26, -16.60, -17.67, -11.54, -0.32, 10.58), "N.m", "asymmetric friction offset")
    cb_D: float = param(0.8, "m", "counterbalance: distance joint 2 to the cylinder's base pivot")
    cb_k: float = param(0.2, "m", "counterbalance: crank radius on link 2")
    cb_Z: float = param(1.01, "1", "counterbalance: gas compressibility factor")
    cb_R: float = param(296.8, "J/(kg.K)", "counterbalance: gas constant of nitrogen")
    cb_T: float = param(328.0, "K", "counterbalance: gas temperature")
    cb_m: float = param(0.159, "kg", "counterbalance: gas mass")
    cb_V: float = param(9.6e-4, "m3", "counterbalance: gas volume at zero stroke")
    cb_A: float = param(math.pi * (0.055**2 - 0.03**2) / 4, "m2", "counterbalance: annular piston area")
    cb_delta0: float = param(math.radians(95.0), "rad", "counterbalance: q_DH2 + cb_delta0 is the crank angle")


def arm_links(P) -> list[Link]:
    """The six :class:`Link` objects from unpacked parameters ``P`` (payload lumped into link 6)."""
    links = []
    for j in _J6:
        mass, com = P.m[j], ca.vertcat(P.rcx[j], P.rcy[j], P.rcz[j])
        if j == 5:
            mass = P.m[j] + P.m_payload
            com = (P.m[j] * com + P.m_payload * ca.vertcat(0, 0, P.r_payload)) / mass
        inertia = ca.vertcat(ca.horzcat(P.Ixx[j], P.Ixy[j], P.Ixz[j]),
                             ca.horzcat(P.Ixy[j], P.Iyy[j], P.Iyz[j]),
                             ca.horzcat(P.Ixz[j], P.Iyz[j], P.Izz[j]))
        links.append(Link(P.d[j], P.a[j], P.alpha[j], mass, com, inertia, P.gear[j] ** 2 * P.J_m[j]))
    return links


def arm_friction(qd, P, f_b_cap=None) -> ca.SX:
    """Identified link-side friction torque (6, 1) in N m; ``f_b_cap`` caps the stiction slope."""
    terms = []
    for j in _J6:
        f_b = P.f_b[j] if f_b_cap is None else ca.fmin(P.f_b[j], f_b_cap)
        terms.append(P.f_asym[j] + P.f_vis[j] * qd[j] + P.f_coul[j] * ca.tanh(qd[j])
                     + P.f_a[j] * ca.tanh(f_b * qd[j]))
    return ca.vertcat(*terms)


def counterbalance_torque(q_dh2, P):
    """Load torque (N m) of the hydraulic counterbalance on joint 2, from the DH angle ``q_dh2`` (rad)."""
    delta = q_dh2 + P.cb_delta0
    stroke = ca.sqrt(P.cb_D**2 + P.cb_k**2 - 2 * P.cb_D * P.cb_k * ca.cos(delta)) - (P.cb_D - P.cb_k)
    pressure = P.cb_Z * P.cb_R * P.cb_T * P.cb_m / (P.cb_V - stroke * P.cb_A)
    return ca.sin(delta) * P.cb_D * P.cb_k / (stroke + P.cb_D - P.cb_k) * pressure * P.cb_A


def _arm_rhs(x, u, P, f_b_cap):
    q, qd = x[:6], x[6:]
    theta = q + ca.DM(THETA_OFFSET)
    base_acc = ca.vertcat(0, 0, -P.g)  # R_base^T [0, 0, g] with R_base = rotx(180 deg)
    tau_cb = ca.vertcat(0, counterbalance_torque(q[1] + Q_DH_OFFSET[1], P), 0, 0, 0, 0)
    tau_link = ca.DM(P.gear) * u - arm_friction(qd, P, f_b_cap) - tau_cb
    return ca.vertcat(qd, forward_dynamics(arm_links(P), theta, qd, tau_link, base_acc))


def arm_system(params: ArmParams | None = None, *, f_b_cap: float | None = ARM_F_B_CAP) -> PhysicsSystem:
    """The arm as a :class:`PhysicsSystem` (Ts = 0.1 s, :data:`ARM_N_SUB` RK4 sub-steps).

    Parameters
    ----------
    params : ArmParams, optional
        Physical parameters (default: physics.md's identified values, 150 kg payload).
    f_b_cap : float or None
        Cap on the stiction slope in s/rad, appended to ``p`` as parameter
        ``f_b_cap``. None: the exact, stiff identified friction (no extra parameter);
        use it only with an implicit integrator.
    """
    params = ArmParams() if params is None else params
    m = ModelBuilder("arm", Ts=ARM_TS, n_sub=ARM_N_SUB,
                     description="KUKA KR300 R2500 rigid arm with friction and counterbalance (physics.md section 3), "
                                 "RK4",
                     source={"model": "nnfmu.physics.arm", "params": params_to_json(params), "f_b_cap": f_b_cap})
    q = [m.state(f"q{j + 1}", "rad", f"angle of joint {j + 1}") for j in _J6]
    qd = [m.state(f"qd{j + 1}", "rad/s", f"velocity of joint {j + 1}", scale=0.5) for j in _J6]
    u = ca.vertcat(*[m.input(c.name, c.unit, c.description, min=lo, max=hi)
                     for c, (lo, hi) in zip(ROBOT_INPUTS, ARM_TAU_LIMITS_NM, strict=True)])
    P = m.parameters_from(params)
    cap = None if f_b_cap is None else m.parameter("f_b_cap", float(f_b_cap), "s/rad",
                                                   "cap on the stiction slope f_b used by the ODE")
    m.ode(_arm_rhs(ca.vertcat(*q, *qd), u, P, cap))
    measured = [m.output(c.name, c.unit, c.description, q[j] * (180.0 / math.pi)) for j, c in enumerate(ROBOT_OUTPUTS)]
    m.init(**{f"q{j + 1}": measured[j] * (math.pi / 180.0) for j in _J6})  # the velocities start at 0
    return m.build()

