"""The FMI 2.0 / 3.0 state machines, the error state, and FMU states restored into a fresh instance."""

from __future__ import annotations

import numpy as np
import pytest
from fmu_cases import MODELS, FMICallException, Instance, built_fmu, excitation

VERSIONS = [2, 3]


def _enter_init(inst: Instance) -> None:
    if inst.fmi3:
        inst.fmu.enterInitializationMode(startTime=0.0)
    else:
        inst.fmu.setupExperiment(startTime=0.0)
        inst.fmu.enterInitializationMode()


# (what the importer does wrongly, in which state, the state named in the message)
CALLS = [
    ("set an input after terminate", lambda i: (i.initialize(), i.fmu.terminate(), i.set({"force": 1.0})),
     "is not allowed in the terminated state"),
    ("step after terminate", lambda i: (i.initialize(), i.fmu.terminate(), i.step(0.01)),
     "is not allowed in the terminated state"),
    ("step before initialization", lambda i: i.step(0.01), "is not allowed in the instantiated state"),
    ("step in initialization mode", lambda i: (_enter_init(i), i.step(0.01)), "is not allowed in initialization mode"),
    ("get a value before initialization", lambda i: i.get(["pos"]), "is not allowed in the instantiated state"),
    ("terminate in initialization mode", lambda i: (_enter_init(i), i.fmu.terminate()),
     "is not allowed in initialization mode"),
    ("initialize twice", lambda i: (i.initialize(), _enter_init(i)), "is not allowed in step mode"),
]


@pytest.mark.parametrize("version", VERSIONS)
@pytest.mark.parametrize("what, call, message", CALLS, ids=[c[0] for c in CALLS])
def test_calls_the_state_machine_forbids_are_errors_with_a_message(version, what, call, message):
    inst = Instance(built_fmu("linear", version))
    with pytest.raises(FMICallException):
        call(inst)
    assert message in inst.errors()[-1] and "FMI allows it in" in inst.errors()[-1], inst.logs
    inst.close()


@pytest.mark.parametrize("version", VERSIONS)
def test_after_an_error_only_reset_free_get_and_fmu_states_work(version):
    model = MODELS["linear"]
    u = excitation(model, 20)
    inst = Instance(built_fmu("linear", version)).initialize()
    inst.run(model, u[:5])
    saved = inst.get_state()
    with pytest.raises(FMICallException):
        inst.set({"Ts": 2.0})
    with pytest.raises(FMICallException):
        inst.step(0.01)
    assert "is not allowed in the error state" in inst.errors()[-1] and "call reset" in inst.errors()[-1]
    np.testing.assert_allclose(inst.get(["time"]), [0.05])  # getters still answer
    inst.set_state(saved)  # back to step mode, where it was saved
    expected = model.simulate(u, [0.1, 0.0])
    np.testing.assert_allclose(inst.run(model, u[5:10]), expected[6:11], rtol=1e-13)
    inst.reset()
    inst.initialize()
    np.testing.assert_allclose(inst.run(model, u[:3]), expected[1:4], rtol=1e-13)
    inst.close()


@pytest.mark.parametrize("version", VERSIONS)
def test_a_state_deserialized_into_a_fresh_instance_resumes(version):
    """As fmusim --initial-fmu-state-file does: instantiate, deserialize, set the state, doStep; no initialization."""
    model = MODELS["nonlinear"]
    u = excitation(model, 60)
    first = Instance(built_fmu("nonlinear", version), "first").initialize({"s_start": 0.3, "gain": 0.7},
                                                                         start_time=2.0)
    first.run(model, u[:25])
    blob = first.serialize(first.get_state())
    continued = first.run(model, u[25:])
    fresh = Instance(built_fmu("nonlinear", version), "fresh")  # instantiated only
    fresh.set_state(fresh.deserialize(blob))
    assert fresh.fmu_time() == pytest.approx(2.0 + 25 * model.spec.Ts, rel=1e-15)
    np.testing.assert_array_equal(fresh.run(model, u[25:]), continued)
    expected = model.simulate(np.vstack([u, u[-1:]]), [0.3, 1.0], [0.7, 0.2])  # 60 steps reach y[60]
    np.testing.assert_allclose(continued, expected[26:], rtol=1e-12)
    first.close()
    fresh.close()


@pytest.mark.parametrize("version", VERSIONS)
def test_a_state_keeps_the_input_held_between_sample_instants(version):
    """Saved halfway between two sample instants, the state holds the input of the last instant."""
    model = MODELS["linear"]
    Ts = model.spec.Ts
    a = Instance(built_fmu("linear", version)).initialize()
    a.set({"force": 2.0})
    a.step(Ts / 2)
    blob = a.serialize(a.get_state())
    a.set({"force": -5.0})  # set between instants: the sample from t = 0 still uses 2.0
    a.step(Ts / 2)
    b = Instance(built_fmu("linear", version))
    b.set_state(b.deserialize(blob))
    b.set({"force": -5.0})
    b.step(Ts / 2)
    np.testing.assert_array_equal(b.get(["pos", "vel"]), a.get(["pos", "vel"]))
    np.testing.assert_allclose(a.get(["pos", "vel"]), model.simulate(np.array([[2.0], [0.0]]), [0.1, 0.0])[1],
                               rtol=1e-14)
    a.close()
    b.close()


def test_a_state_of_another_fmu_is_refused():
    mine = Instance(built_fmu("linear", 2)).initialize()
    blob = mine.serialize(mine.get_state())
    other = Instance(built_fmu("linear_twin", 2))  # same name and variables, another build
    with pytest.raises(FMICallException):
        other.deserialize(blob)
    assert "not a serialized state of this FMU" in other.errors()[-1]
    mine.close()
    other.close()
