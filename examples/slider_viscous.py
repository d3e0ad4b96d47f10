"""The slider (nnfmu's built-in mass on a rail) with only its mass and viscous friction.

The built-in slider also has Coulomb and Stribeck friction; this model leaves them out, on purpose:
it is the mis-specified physics of the grey-box and hybrid study (issue 23), where a learned
correction has to supply the missing friction::

    m dv/dt = F - d v        dpos/dt = v        y = pos

A hybrid on it corrects ``dv/dt`` only (``dpos/dt = v`` is a kinematic identity) and its network sees ``v``
and ``F``, not ``pos`` (no derivative depends on it): the defaults of ``HybridConfig`` for such states.

    nnfmu info examples/slider_viscous.py
"""

from nnfmu.physics import ModelBuilder


def slider_viscous():
    m = ModelBuilder("slider_viscous", Ts=0.01, n_sub=4, settle_time=0.5,
                     description="mass on a rail with viscous friction only, driven by a force")
    pos = m.state("pos", "m", "position of the mass on the rail")
    v = m.state("v", "m/s", "velocity of the mass")
    F = m.input("F", "N", "driving force", min=-6.0, max=6.0)
    mass = m.parameter("m", 1.0, "kg", "moving mass", min=0.05, max=20.0)
    d = m.parameter("d", 2.0, "N.s/m", "viscous friction", min=0.0, max=50.0)
    m.ode(pos=v, v=(F - d * v) / mass)
    m.output("pos", "m", "measured position of the mass", pos)
    return m.build()
