"""Two tanks in cascade, the model of the tutorial "Your own physics model" (docs/own-physics.md).

A pump (voltage ``u``, in V) fills the upper tank; it drains through a hole into the lower tank, which
drains through its own hole. Only the lower tank's level is measured (as in the Cascaded Tanks benchmark)::

    A1 dh1/dt = k_p u      - a1 sqrt(2 g h1)
    A2 dh2/dt = a1 sqrt(2 g h1) - a2 sqrt(2 g h2)        y = h2

Torricelli's law ``a sqrt(2 g h)`` is smoothed below 1 mm of water (:func:`outflow`), so that the
derivatives stay finite at an empty tank. The tank cross-sections are known (not fitted); the outlet
areas and the pump gain are the free parameters.

    nnfmu info examples/two_tanks.py
    nnfmu physics-fmu examples/two_tanks.py:two_tanks -o two_tanks.fmu
    nnfmu generate examples/two_tanks.py:two_tanks -o tanks_data --noise 0.01
"""

import casadi as ca

from nnfmu.physics import ModelBuilder

G = 9.81        # m/s2
H_EPS = 1e-3    # m: below this level the outflow law turns linear


def outflow(a, h):
    """Volume flow in m3/s through an outlet of area ``a`` (m2) under the level ``h`` (m), Torricelli's law."""
    return a * ca.sqrt(2 * G) * h / (h * h + H_EPS * H_EPS) ** 0.25


def two_tanks():
    m = ModelBuilder("two_tanks", Ts=1.0, n_sub=2, settle_time=100.0,
                     description="two tanks in cascade, pump voltage in, lower level out")
    h1 = m.state("h1", "m", "level of the upper tank", scale=0.3)
    h2 = m.state("h2", "m", "level of the lower tank", scale=0.3)
    u = m.input("u", "V", "pump voltage", min=0.0, max=10.0)
    A1 = m.parameter("A1", 0.0154, "m2", "cross-section of the upper tank", free=False)
    A2 = m.parameter("A2", 0.0154, "m2", "cross-section of the lower tank", free=False)
    a1 = m.parameter("a1", 5e-5, "m2", "outlet area of the upper tank", min=1e-6, max=1e-3)
    a2 = m.parameter("a2", 6e-5, "m2", "outlet area of the lower tank", min=1e-6, max=1e-3)
    k_p = m.parameter("k_p", 1.5e-5, "m3/(s.V)", "pump gain", min=1e-7, max=1e-3)
    m.ode(h1=(k_p * u - outflow(a1, h1)) / A1,
          h2=(outflow(a1, h1) - outflow(a2, h2)) / A2)
    y0 = m.output("h2", "m", "measured level of the lower tank", h2, start=0.1, min=0.0, max=0.5)
    # The upper level is not measured: start where it would be at rest (equal flows through both outlets).
    m.init(h1=y0 * (a2 / a1) ** 2)
    return m.build()
