"""Two-stage pneumatic valve: a generic CasADi SX model (physics.md section 1).

Two piezo benders (inputs ``u1``, ``u2`` in V) open pilot orifices from the
supply into a control chamber and from the chamber to the exhaust. The
chamber pressure ``p`` pushes a spring-returned plunger whose position ``s``
is the second output. The plunger has stiff, smooth end stops at ``s = 0``
(closed) and ``s = s_max`` (fully open).

States ``x = [z1, z1dot, z2, z2dot, p, s, sdot]`` (m, m/s, m, m/s, Pa, m, m/s);
inputs ``u = [u1, u2]`` (V); outputs ``y = [s, p]`` (m, Pa); Ts = 40 us.

Every number in :class:`ValveParams` is an assumption from the pneumatics
literature (physics.md), not an identified value. The three smoothing widths
(``eps_lift``, ``eps_sat``, ``eps_stop``) are modelling choices that keep the
ODE differentiable; they are parameters too, so that nothing is hidden.

Behaviour of the default parameters (checked in tests/test_physics_valve.py):
with the supply pilot fully open, p reaches 90 % of its final value in about
5 ms; the plunger lifts off at about 2.0 bar and reaches 1 mm at about
5.2 bar; with both pilots at 120 V, p settles near 5.45 bar.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import casadi as ca

from nnfmu.physics.base import PhysicsSystem, param, params_to_json
from nnfmu.physics.builder import ModelBuilder
from nnfmu.system import Variable

__all__ = ["ValveParams", "valve_system", "VALVE_TS", "VALVE_U_MAX", "VALVE_STATES"]

VALVE_TS = 40e-6
VALVE_U_MAX = 250.0

VALVE_STATES = (
    Variable("z1", "m", "tip deflection of the supply-pilot bender"),
    Variable("z1dot", "m/s", "tip velocity of the supply-pilot bender"),
    Variable("z2", "m", "tip deflection of the exhaust-pilot bender"),
    Variable("z2dot", "m/s", "tip velocity of the exhaust-pilot bender"),
    Variable("p", "Pa", "control-chamber pressure (absolute)"),
    Variable("s", "m", "plunger position (0 closed, s_max fully open)"),
    Variable("sdot", "m/s", "plunger velocity"),
)
_STATE_SCALES = (1e-4, 0.5, 1e-4, 0.5, 5e5, 1e-3, 0.5)
# The piezo drive range [0, VALVE_U_MAX] is the inputs' valid range: an FMU of the model declares it as min/max.
_INPUTS = (Variable("u1", "V", "piezo voltage of the supply pilot (opens supply -> chamber)", min=0.0, max=VALVE_U_MAX),
           Variable("u2", "V", "piezo voltage of the exhaust pilot (opens chamber -> exhaust)", min=0.0,
                    max=VALVE_U_MAX))
_OUTPUTS = (Variable("s", "m", "plunger position"), Variable("p", "Pa", "control-chamber pressure (absolute)"))


@dataclass(frozen=True, kw_only=True)
class ValveParams:
    """Physical parameters of the valve (physics.md table); ``dataclasses.replace`` makes variants."""

    p_s: float = param(7.0e5, "Pa", "supply pressure (absolute)")
    p_a: float = param(1.013e5, "Pa", "ambient / exhaust pressure (absolute)")
    T: float = param(293.15, "K", "air temperature (isothermal sources)")
    R: float = param(287.05, "J/(kg.K)", "specific gas constant of air")
    n: float = param(1.3, "1", "polytropic exponent of the chamber")
    rho0: float = param(1.185, "kg/m3", "ISO 6358 reference density")
    T0: float = param(293.15, "K", "ISO 6358 reference temperature")
    C_max: float = param(6e-10, "m3/(s.Pa)", "sonic conductance of a fully open pilot")
    b: float = param(0.4, "1", "critical pressure ratio")
    beta_lam: float = param(0.995, "1", "pressure ratio where the flow becomes laminar (linear to 0)")
    V0: float = param(0.3e-6, "m3", "dead volume of the control chamber")
    A_p: float = param(7.85e-5, "m2", "plunger area (10 mm diameter)")
    m_p: float = param(5e-3, "kg", "plunger mass")
    s_max: float = param(1.0e-3, "m", "plunger stroke")
    F0: float = param(8.0, "N", "spring preload")
    k_s: float = param(25e3, "N/m", "spring stiffness")
    d_p: float = param(5.0, "N.s/m", "viscous friction of the plunger")
    F_C: float = param(0.5, "N", "Coulomb friction of the plunger")
    v_eps: float = param(1e-3, "m/s", "velocity scale of the smoothed Coulomb friction")
    k_c: float = param(5e6, "N/m", "end-stop contact stiffness")
    d_c: float = param(220.0, "N.s/m", "end-stop contact damping")
    f_b: float = param(1000.0, "Hz", "bender natural frequency")
    zeta_b: float = param(0.3, "1", "bender damping ratio")
    d_u: float = param(0.4e-6, "m/V", "bender static gain (tip deflection per volt)")
    z0: float = param(20e-6, "m", "seat offset: deflection at which a pilot starts to open")
    h_sat: float = param(60e-6, "m", "lift at which a pilot is fully open")
    eps_lift: float = param(2e-6, "m", "smoothing width of the lift softplus")
    eps_sat: float = param(0.02, "1", "smoothing width of the conductance saturation")
    eps_stop: float = param(1e-6, "m", "smoothing width of the end-stop contact")


def _softplus(x, eps):
    """``eps * log(1 + exp(x / eps))``, overflow-free: a smooth ``max(x, 0)`` of width ``eps``."""
    return eps * ca.log1p(ca.exp(-ca.fabs(x) / eps)) + ca.fmax(x, 0)


def _sigmoid(x, eps):
    """Smooth step from 0 to 1 around ``x = 0`` with width ``eps``."""
    return 0.5 * (1.0 + ca.tanh(x / (2.0 * eps)))


def _flow_function(r, P):
    """ISO 6358 flow function ``phi(r)`` of the pressure ratio ``r`` in [0, 1], with a laminar end."""
    phi_sub = ca.sqrt(ca.fmax(1.0 - ((r - P.b) / (1.0 - P.b)) ** 2, 0.0))
    phi_lam = _laminar_slope(P) * (1.0 - r)
    return ca.if_else(r <= P.b, 1.0, ca.if_else(r <= P.beta_lam, phi_sub, phi_lam))


def _laminar_slope(P):
    """``-dphi/dr`` of the laminar end: ``phi`` falls linearly from ``phi(beta_lam)`` to 0 at ratio 1."""
    return ca.sqrt(1.0 - ((P.beta_lam - P.b) / (1.0 - P.b)) ** 2) / (1.0 - P.beta_lam)


def _mass_flow(conductance, p_from, p_to, P):
    """Mass flow in kg/s from ``p_from`` to ``p_to`` (negative when the pressures cross).

    Above the ratio ``beta_lam`` the laminar end ``p_hi * phi(r)`` is written as what it equals, the signed
    pressure difference times a constant: through ``fmax``/``fmin`` and ``r = p_lo / p_hi``, AD lost the derivative
    exactly at ratio 1 (both pressures equal: ``dr/dp`` is 0 at the tie), the state every ME run of the valve
    starts from. The values are the same to rounding.
    """
    p_hi, p_lo = ca.fmax(p_from, p_to), ca.fmin(p_from, p_to)
    r = p_lo / p_hi
    gain = conductance * P.rho0 * ca.sqrt(P.T0 / P.T)
    magnitude = p_hi * _flow_function(r, P)
    return gain * ca.if_else(r > P.beta_lam, _laminar_slope(P) * (p_from - p_to),
                             ca.if_else(p_from >= p_to, magnitude, -magnitude))


def _conductance(z, P):
    """Pilot conductance from the bender deflection: softplus lift, smooth saturation at h_sat."""
    opening = _softplus(z - P.z0, P.eps_lift) / P.h_sat
    return P.C_max * (opening - _softplus(opening - 1.0, P.eps_sat))


def _plunger_force(p, s, sdot, P):
    """Net force on the plunger in N: pressure, spring, friction and the two end stops."""
    stop = (P.k_c * (_softplus(-s, P.eps_stop) - _softplus(s - P.s_max, P.eps_stop))
            - P.d_c * sdot * (_sigmoid(-s, P.eps_stop) + _sigmoid(s - P.s_max, P.eps_stop)))
    return ((p - P.p_a) * P.A_p - P.F0 - P.k_s * s - P.d_p * sdot
            - P.F_C * ca.tanh(sdot / P.v_eps) + stop)


def _valve_rhs(x, u, P):
    z1, z1dot, z2, z2dot, p, s, sdot = (x[i] for i in range(7))
    w_b = 2.0 * math.pi * P.f_b
    bender = [w_b**2 * (P.d_u * u[i] - z) - 2.0 * P.zeta_b * w_b * zdot
              for i, (z, zdot) in enumerate(((z1, z1dot), (z2, z2dot)))]
    mdot_in = _mass_flow(_conductance(z1, P), P.p_s, p, P)
    mdot_out = _mass_flow(_conductance(z2, P), p, P.p_a, P)
    volume = P.V0 + P.A_p * s
    pdot = P.n * P.R * P.T / volume * (mdot_in - mdot_out) - P.n * p * P.A_p * sdot / volume
    sddot = _plunger_force(p, s, sdot, P) / P.m_p
    return ca.vertcat(z1dot, bender[0], z2dot, bender[1], pdot, sdot, sddot)


def valve_system(params: ValveParams | None = None) -> PhysicsSystem:
    """The valve as a :class:`PhysicsSystem` (Ts = 40 us, 4 RK4 sub-steps by default), written with
    :class:`ModelBuilder`.

    Parameters
    ----------
    params : ValveParams, optional
        Physical parameters; the defaults are physics.md's table. They are
        the nominal values of the ``p`` port, not baked in.
    """
    params = ValveParams() if params is None else params
    m = ModelBuilder("valve", Ts=VALVE_TS, n_sub=4,
                     description="two-stage pneumatic valve (generic model, physics.md section 1), RK4",
                     source={"model": "nnfmu.physics.valve", "params": params_to_json(params)})
    x = ca.vertcat(*[m.state(v.name, v.unit, v.description, scale=scale)
                     for v, scale in zip(VALVE_STATES, _STATE_SCALES, strict=True)])
    u = ca.vertcat(*[m.input(v.name, v.unit, v.description, min=v.min, max=v.max) for v in _INPUTS])
    P = m.parameters_from(params)
    m.ode(_valve_rhs(x, u, P))
    # at rest: both pilots closed (0 V), the plunger on its seat, the chamber at ambient pressure
    m.output(_OUTPUTS[0].name, _OUTPUTS[0].unit, _OUTPUTS[0].description, x[5])
    m.output(_OUTPUTS[1].name, _OUTPUTS[1].unit, _OUTPUTS[1].description, x[4], start=params.p_a)
    # Benders at their static deflection, plunger and benders at rest; s and p from the measurement.
    m.init(z1=P.d_u * u[0], z2=P.d_u * u[1])
    return m.build()

