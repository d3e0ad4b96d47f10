"""A physics model from outside nnfmu: a first-order lag, registered with a study of its own.

Loaded as a user loads a plug-in (``NNFMU_PLUGINS=toy_physics``, its folder on the path); nothing inside
``nnfmu/`` names it. It has no generator of its own, so ``nnfmu generate`` excites it with the toolkit's
signals within its input's range.
"""

from nnfmu.physics import ModelBuilder, PhysicsEntry, StudyPreset, register_physics


def toy_lag():
    m = ModelBuilder("toy_lag", Ts=0.1, n_sub=2, settle_time=2.0, description="a first-order lag, gain K, time T")
    x = m.state("x", "m", "the lagging position", scale=1.0)
    u = m.input("u", "V", "the command", min=-1.0, max=1.0)
    gain = m.parameter("K", 2.0, "m/V", "static gain", min=0.1, max=10.0)
    tau = m.parameter("T", 0.5, "s", "time constant", min=0.05, max=5.0)
    m.ode(x=(gain * u - x) / tau)
    m.output("y", "m", "the measured position", x)
    return m.build()


TOY_STUDY = StudyPreset(name="toy_lag", title="Toy lag (generated data)", data_sizes=("standard", "small"),
                        physics_label="Physics model (the toy lag that generated the data, RK4)",
                        note="The toy lag generated the data{noise_floor}; its row is a reference.")

register_physics(PhysicsEntry("toy_lag", toy_lag, title="A first-order lag", studies=(TOY_STUDY,)))
