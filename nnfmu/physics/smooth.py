"""Smooth stand-ins for the kinks a physics model needs, with exact derivatives at the kink.

For ``ModelBuilder`` files (docs/own-physics.md)::

    from nnfmu.physics.smooth import smooth_abs, smooth_clip, smooth_max, smooth_min, smooth_sign, smooth_sqrt

    q = a * ca.sqrt(2 * G) * smooth_sqrt(h1 - h2, 1e-3)       # outflow between tanks (signed, laminar near 0)
    F_friction = d * v + F_c * smooth_sign(v, 1e-3)             # viscous and Coulomb friction
    u_pump = smooth_clip(u, 0.0, 10.0, 0.05)                     # an actuator that saturates

Why. The sharp functions (``sqrt`` of a difference, ``sign``, ``fmax``) have a kink where models rest (equal
levels, zero velocity, an input at its limit). There an RK4 step needs tiny sub-steps and a fit's Jacobian is
infinite or NaN (CasADi's derivative of ``sign(x) sqrt(fabs(x))`` at 0 is NaN). CasADi's AD takes ``fabs``'s
slope at 0 as 0 and ``fmax``'s at a tie as 1/2 each, and a model built from them is right at the kink only
when those conventions happen to combine to the true slope: the valve's ratio ``fmin(p) / fmax(p)`` lost
``dp/dp`` at the pressure ratio 1 (issue 37; :func:`nnfmu.physics.valve._mass_flow` now writes the laminar end
as the signed difference times a constant), and Model Exchange hands that Jacobian to the importer's solver.
Each helper here is one analytic formula through its kink (or two branches that are the same analytic
function, each used where it cannot overflow), so CasADi's derivative there is the analytic one, finite
(tests/test_smooth.py).

Every helper takes a smoothing width ``eps`` (> 0) **in the unit of its argument** (m for a level difference, m/s
for a velocity, V for a voltage); the sharp function is recovered as ``eps -> 0``, and each docstring bounds the
error. Choose ``eps`` well below the values that matter and well above the noise or the numerical scale
(a hundredth of the argument's typical range is a usual start). The arguments may be CasADi SX or MX symbols,
DM or Python floats.
"""

from __future__ import annotations

import math

import casadi as ca

__all__ = ["smooth_abs", "smooth_sign", "smooth_sqrt", "smooth_max", "smooth_min", "smooth_clip"]

#: Largest exponent a non-taken branch of :func:`smooth_max` evaluates (``exp(30)`` is finite; far from the kink).
_EXP_CAP = 30.0


def smooth_sign(x, eps):
    """``tanh(x / eps)``: a smooth ``sign(x)`` (Coulomb friction, a valve's flow direction).

    ``eps``: the width, in the unit of ``x``. Slope ``1 / eps`` at 0. Error: ``|sign(x) - smooth_sign(x)| <=
    2 exp(-2 |x| / eps)`` (below 0.5 % from ``|x| = 3 eps``); 0 at 0.
    """
    return ca.tanh(x / eps)


def smooth_abs(x, eps):
    """``x tanh(x / eps)``: a smooth ``|x|`` (quadratic drag ``v |v|``, a magnitude), exactly 0 at 0.

    ``eps``: the width, in the unit of ``x``. Slope 0 at 0. Error: ``0 <= |x| - smooth_abs(x) <= 0.28 eps``, and
    ``<= 2 |x| exp(-2 |x| / eps)``.
    """
    return x * ca.tanh(x / eps)


def smooth_sqrt(x, eps):
    """``x / (x^2 + eps^2)^(1/4)``: a smooth signed square root ``sign(x) sqrt(|x|)`` (Torricelli and orifice flow
    under a level or pressure difference ``x``; linear, laminar, for ``|x|`` below about ``eps``).

    ``eps``: the width, in the unit of ``x`` (the result is in the square root of that unit). Slope
    ``1 / sqrt(eps)`` at 0, where the sharp function's is infinite. Error: ``|sign(x) sqrt|x| - smooth_sqrt(x)|
    <= 0.26 sqrt(eps)``, and relative to ``sqrt|x|`` at most ``eps^2 / (4 x^2)``.
    """
    return x / (x * x + eps * eps) ** 0.25


def smooth_max(a, b, eps):
    """``eps log(exp(a / eps) + exp(b / eps))``: a smooth ``max(a, b)`` (a saturation, a level that stays
    non-negative, a one-way valve).

    ``eps``: the width, in the unit of ``a`` and ``b``. At ``a = b`` the value is ``a + eps ln 2`` and both slopes
    are 1/2. Error: ``0 <= smooth_max(a, b) - max(a, b) <= eps ln 2``, and ``<= eps exp(-|a - b| / eps)``.

    Written as two branches, ``a + eps log1p(exp((b - a) / eps))`` for ``a > b`` and the mirror for ``a <= b``:
    the same analytic function, each taken where its exponential stays below 1 (the other's exponent is capped
    far from the kink), so neither overflows and the derivative at the tie is the formula's own.
    """
    d = (a - b) / eps
    above = a + eps * ca.log1p(ca.exp(ca.fmin(-d, _EXP_CAP)))
    below = b + eps * ca.log1p(ca.exp(ca.fmin(d, _EXP_CAP)))
    return ca.if_else(d > 0, above, below)


def smooth_min(a, b, eps):
    """``-smooth_max(-a, -b, eps)``: a smooth ``min(a, b)``. Error: ``-eps ln 2 <= smooth_min(a, b) - min(a, b)
    <= 0``; slopes 1/2 at ``a = b``. ``eps`` in the unit of ``a`` and ``b``."""
    return -smooth_max(-a, -b, eps)


def smooth_clip(x, lo, hi, eps):
    """``smooth_min(smooth_max(x, lo), hi)``: ``x`` saturated smoothly to ``[lo, hi]`` (an actuator's range, a
    tank's overflow level), for ``lo < hi``.

    ``eps``: the width at each limit, in the unit of ``x``. Error: ``|smooth_clip(x) - clip(x, lo, hi)| <=
    eps ln 2`` (at ``x = lo`` it is ``+eps ln 2``, at ``x = hi`` ``-eps ln 2``); keep ``hi - lo`` well above
    ``eps`` so that the two ends do not meet.
    """
    return smooth_min(smooth_max(x, lo, eps), hi, eps)


#: ``0.28 eps``, ``0.26 sqrt(eps)``: the largest errors of :func:`smooth_abs` and :func:`smooth_sqrt`, rounded up
#: (the maxima of ``t (1 - tanh t)`` and ``sqrt t - t / (1 + t^2)^(1/4)``: 0.2785 and 0.2543).
ERROR_BOUNDS = {"smooth_abs": 0.28, "smooth_sqrt": 0.26, "smooth_max": math.log(2.0)}
