"""Slider: a mass on a rail with friction, driven by a force, its position measured.

An integrating plant: the position is the integral of the velocity, so it has
no equilibrium of its own (marginally stable) and wanders over the record,
beyond the range any finite training set covers. The friction is a smooth
Stribeck curve (viscous, Coulomb and a static peak at low speed), so small
forces leave the mass stuck and a linear model cannot be exact::

    m dv/dt = F - d v - (F_c + (F_s - F_c) exp(-(v / v_st)^2)) tanh(v / v_eps)
    dx/dt   = v

States ``x = [pos, v]`` (m, m/s); input ``F`` (N); output ``pos`` (m); Ts = 10 ms.
The dynamics do not depend on the position (a rail without stops): shifting
the position shifts the whole response.
"""

from __future__ import annotations

from dataclasses import dataclass

import casadi as ca

from nnfmu.physics.base import PhysicsSystem, param, params_to_json
from nnfmu.physics.builder import ModelBuilder

__all__ = ["SliderParams", "slider_system", "SLIDER_TS", "SLIDER_F_MAX"]

SLIDER_TS = 0.01
SLIDER_F_MAX = 6.0

@dataclass(frozen=True, kw_only=True)
class SliderParams:
    """Physical parameters of the slider (a small linear axis); ``dataclasses.replace`` makes variants."""

    m: float = param(1.0, "kg", "moving mass")
    d: float = param(2.0, "N.s/m", "viscous friction")
    F_c: float = param(1.5, "N", "Coulomb friction")
    F_s: float = param(2.5, "N", "static (breakaway) friction")
    v_st: float = param(0.05, "m/s", "Stribeck velocity")
    v_eps: float = param(0.005, "m/s", "velocity scale of the smoothed sign of the friction")


def _friction(v, P):
    """Friction force in N opposing the velocity ``v``: viscous plus the smoothed Stribeck curve."""
    level = P.F_c + (P.F_s - P.F_c) * ca.exp(-(v / P.v_st) ** 2)
    return P.d * v + level * ca.tanh(v / P.v_eps)


def slider_system(params: SliderParams | None = None) -> PhysicsSystem:
    """The slider as a :class:`PhysicsSystem` (Ts = 10 ms, 4 RK4 sub-steps), written with :class:`ModelBuilder`.

    The smoothed sign makes the ODE stiff near zero speed (rate ``F_s / (m v_eps)`` = 500 1/s
    with the defaults); 4 sub-steps of 2.5 ms keep RK4 inside its stability region.
    """
    params = SliderParams() if params is None else params
    m = ModelBuilder("slider", Ts=SLIDER_TS, n_sub=4,
                     description="mass on a rail with Stribeck friction driven by a force (an integrating plant), RK4",
                     source={"model": "nnfmu.physics.slider", "params": params_to_json(params)})
    pos = m.state("pos", "m", "position of the mass on the rail")
    v = m.state("v", "m/s", "velocity of the mass")
    F = m.input("F", "N", "driving force")
    P = m.parameters_from(params)
    m.ode(pos=v, v=(F - _friction(v, P)) / P.m)
    m.output("pos", "m", "measured position of the mass", pos)  # x0: pos from the measurement, v = 0 (its start)
    return m.build()

