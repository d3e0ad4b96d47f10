"""The FMU in fmpy: it equals CasadiModel.simulate, and its FMI behaviour (state, errors, instances).

Stepping is tested in test_fmu_stepping.py, the state machine in test_fmu_state_machine.py."""

from __future__ import annotations

import fmpy
import numpy as np
import pytest
from fmpy.fmi2 import FMU2Slave
from fmu_cases import MODELS, FMICallException, Instance, built_fmu, excitation, fmpy_simulate, unzipped

VERSIONS = [2, 3]


def assert_close(actual, expected, rtol=1e-9):
    """Relative agreement in float64, scaled by the signal's magnitude (outputs cross zero)."""
    actual, expected = np.asarray(actual), np.asarray(expected)
    scale = np.maximum(np.abs(expected).max(axis=0), 1e-300)
    np.testing.assert_array_less(np.abs(actual - expected) / scale, rtol)


@pytest.mark.parametrize("version", VERSIONS)
@pytest.mark.parametrize("name", ["linear", "nonlinear"])
def test_fmpy_simulation_equals_casadi_simulate(name, version):
    model = MODELS[name]
    u = excitation(model, 400, seed=version)
    y0 = np.array([0.05, -0.3])
    expected = model.simulate(u, y0)
    assert_close(fmpy_simulate(built_fmu(name, version), model, u, y0), expected)
    assert np.ptp(expected[:, 0]) > 1e-2, "the test signal must move the outputs"


@pytest.mark.parametrize("version", VERSIONS)
def test_tunable_parameters_feed_the_p_port(version):
    model = MODELS["nonlinear"]
    u, y0, p = excitation(model, 200), np.array([0.2, 0.4]), np.array([0.6, 0.35])
    expected = model.simulate(u, y0, p)
    assert np.abs(expected - model.simulate(u, y0)).max() > 1e-3, "p must change the result"
    assert_close(fmpy_simulate(built_fmu("nonlinear", version), model, u, y0, p), expected)


@pytest.mark.parametrize("version", VERSIONS)
def test_step_of_several_samples_holds_the_input(version):
    model = MODELS["nonlinear"]
    inst = Instance(built_fmu("nonlinear", version)).initialize({"s_start": 0.3, "q_start": -0.1})
    u = np.repeat(excitation(model, 6), 5, axis=0)  # each input held for 5 samples
    expected = model.simulate(np.vstack([u, u[-1:]]), [0.3, -0.1])[5::5]
    got = []
    for k in range(6):
        inst.set({"u1": u[5 * k, 0], "u2": u[5 * k, 1]})
        inst.step(5 * model.spec.Ts)
        got.append(inst.get(["s", "q"]))
    assert_close(got, expected)
    assert inst.fmu_time() == pytest.approx(30 * model.spec.Ts, rel=1e-12)
    inst.close()


@pytest.mark.parametrize("version", VERSIONS)
def test_output_at_start_is_y0_and_start_time_is_respected(version):
    model = MODELS["linear"]
    inst = Instance(built_fmu("linear", version)).initialize({"pos_start": 1.5, "vel_start": -2.0}, start_time=10.0)
    np.testing.assert_array_equal(inst.get(["pos", "vel", "time", "Ts"]), [1.5, -2.0, 10.0, 0.01])
    u = excitation(model, 20)
    assert_close(inst.run(model, u[:-1]), model.simulate(u, [1.5, -2.0])[1:])
    assert inst.fmu_time() == pytest.approx(10.0 + 19 * 0.01, rel=1e-12)
    inst.close()


@pytest.mark.parametrize("version", VERSIONS)
def test_reset_starts_over(version):
    model = MODELS["nonlinear"]
    u = excitation(model, 40)
    inst = Instance(built_fmu("nonlinear", version)).initialize({"s_start": 0.2})
    first = inst.run(model, u)
    inst.reset()
    inst.initialize({"s_start": 0.2})
    np.testing.assert_array_equal(inst.run(model, u), first)
    inst.close()


@pytest.mark.parametrize("version", VERSIONS)
def test_fmu_state_get_set_and_serialize_round_trip(version):
    model = MODELS["nonlinear"]
    u = excitation(model, 60)
    inst = Instance(built_fmu("nonlinear", version)).initialize({"q_start": 0.7})
    inst.run(model, u[:20])
    state = inst.get_state()
    blob = inst.serialize(state)
    after = inst.run(model, u[20:])
    inst.set_state(state)
    np.testing.assert_array_equal(inst.run(model, u[20:]), after)
    restored = inst.deserialize(blob)
    inst.set_state(restored)
    assert inst.fmu_time() == pytest.approx(20 * model.spec.Ts)
    np.testing.assert_array_equal(inst.run(model, u[20:]), after)
    inst.free_state(state)
    inst.free_state(restored)
    with pytest.raises(FMICallException):
        inst.deserialize(blob[:-8])
    assert any("expected" in m and "bytes" in m for m in inst.errors())
    inst.close()


@pytest.mark.parametrize("version", VERSIONS)
def test_instances_side_by_side_do_not_share_state(version):
    model = MODELS["nonlinear"]
    ua, ub = excitation(model, 50, seed=1), excitation(model, 50, seed=2)
    a = Instance(built_fmu("nonlinear", version), "a").initialize({"s_start": 0.1})
    b = Instance(built_fmu("nonlinear", version), "b").initialize({"s_start": -0.4, "gain": 0.5})
    ya, yb = [], []
    for k in range(49):  # interleaved, sample by sample
        ya.append(a.run(model, ua[k:k + 1])[0])
        yb.append(b.run(model, ub[k:k + 1])[0])
    assert_close(ya, model.simulate(ua, [0.1, 1.0])[1:])  # q_start keeps its default 1.0
    assert_close(yb, model.simulate(ub, [-0.4, 1.0], [0.5, 0.2])[1:])
    a.close()
    b.close()


@pytest.mark.parametrize("version", VERSIONS)
@pytest.mark.parametrize("bad", [np.nan, np.inf])
def test_non_finite_input_is_an_error_and_the_step_is_not_taken(version, bad):
    model = MODELS["nonlinear"]
    u = excitation(model, 6)
    inst = Instance(built_fmu("nonlinear", version)).initialize()
    inst.run(model, u[:3])
    before, saved = inst.get(["s", "q", "time"]), inst.get_state()
    inst.set({"u1": bad})
    with pytest.raises(FMICallException):
        inst.fmu.doStep(inst.fmu_time(), model.spec.Ts)
    assert any(f"input u1 must be finite but was {bad}".lower() in m.lower() for m in inst.errors()), inst.logs
    np.testing.assert_array_equal(inst.get(["s", "q", "time"]), before)
    inst.set_state(saved)  # FMI's way on after an error: a state saved before
    assert_close(inst.run(model, u[3:5]), model.simulate(u, [0.0, 1.0])[4:6])
    inst.close()


def test_non_finite_result_is_an_error_not_a_crash():
    model = MODELS["blowup"]
    inst = Instance(built_fmu("blowup", 2)).initialize()
    inst.run(model, np.array([[0.5], [0.5]]))
    with pytest.raises(FMICallException):
        inst.run(model, np.array([[800.0]]))
    assert any("output y became inf" in m for m in inst.errors()), inst.logs
    assert inst.get(["y"])[0] == pytest.approx(np.exp(1.0))


@pytest.mark.parametrize("version", VERSIONS)
def test_variables_that_cannot_be_set(version):
    inst = Instance(built_fmu("linear", version))
    for values, message in (({"Ts": 1.0}, "Ts (value reference 1) is a constant"),
                            ({"pos": 1.0}, "pos is an output and cannot be set"),
                            ({"pos_start": 1.0}, "pos_start is a fixed parameter; set it before exitInit")):
        inst.initialize()
        with pytest.raises(FMICallException):
            inst.set(values)
        assert message in inst.errors()[-1]
        inst.reset()  # an error leaves the instance in the error state
    inst.close()


def test_wrong_guid_is_refused():
    folder = unzipped(built_fmu("linear", 2))
    md = fmpy.read_model_description(str(folder))
    slave = FMU2Slave(guid="{not-this-fmu}", unzipDirectory=str(folder), modelIdentifier="oscillator")
    with pytest.raises(Exception, match="Failed to instantiate"):
        slave.instantiate()
    assert md.guid != "{not-this-fmu}"


def test_two_fmus_with_the_same_name_run_side_by_side_in_one_process():
    """Each binary keeps its model symbols to itself, so same-named FMUs cannot call each other's code."""
    model, twin = MODELS["linear"], MODELS["linear_twin"]
    assert model.spec.name == twin.spec.name
    u = excitation(model, 30)
    a = Instance(built_fmu("linear", 2), "a").initialize({"pos_start": 0.2})
    b = Instance(built_fmu("linear_twin", 2), "b").initialize({"pos_start": 0.2})
    ya, yb = a.run(model, u[:-1]), b.run(twin, u[:-1])
    assert_close(ya, model.simulate(u, [0.2, 0.0])[1:])
    assert_close(yb, twin.simulate(u, [0.2, 0.0])[1:])
    assert np.abs(ya - yb).max() > 1e-3
    a.close()
    b.close()
