"""Model Exchange at input events, as the Reference FMUs' fmusim integrates it.

fmusim (v0.0.39) restarts CVode after an event only when the FMU reports valuesOfContinuousStatesChanged
(or nominalsOfContinuousStatesChanged); fmpy restarts after every event. FMI (2.0 section 3.1, 3.0
section 3.1) makes an input that changes discontinuously an event that the importer triggers, and the
right-hand side is continuous only between events. An nnfmu FMU therefore reports the flag once in an
event where an input or a tunable parameter changed, so that both importers restart there:

- fmusim's rule, emulated on fmpy's own CVode, integrates input steps at a relative tolerance of 1e-10
  (without the flag CVode fails there) and gives fmpy's result, for FMI 2 and FMI 3;
- the flag is set once per change and never without one;
- the range warning of a Model Exchange instance speaks of evaluations, not of steps.
"""

from __future__ import annotations

import ctypes
import dataclasses

import fmpy
import fmpy.fmi2
import fmpy.fmi3
import fmpy.sundials
import numpy as np
import pytest
from fmu_cases import MODELS, built_fmu, instantiate_logged, unzipped
from test_fmu_model_exchange import MeInstance, pendulum

from nnfmu.system import CasadiModel

TORQUE_RANGE = 50.0  # 1/s2: the pendulum's declared input range is +-this


def bounded_pendulum() -> CasadiModel:
    """The damped pendulum of test_fmu_model_exchange with a valid input range of +-TORQUE_RANGE."""
    model = pendulum()
    torque = dataclasses.replace(model.spec.inputs[0], min=-TORQUE_RANGE, max=TORQUE_RANGE)
    return dataclasses.replace(model, spec=dataclasses.replace(model.spec, inputs=(torque,)))


MODELS.setdefault("pendulum", bounded_pendulum())  # built once per session by fmu_cases.built_fmu


def torque_steps(n: int = 300, hold: int = 25) -> tuple[float, np.ndarray]:
    """(Ts, fmpy's input signal): torque held for `hold` samples, then a step (an event) to a new value."""
    Ts = MODELS["pendulum"].spec.Ts
    u = np.repeat(np.random.default_rng(0).uniform(-20.0, 20.0, n // hold + 1), hold)[:n]
    t = np.arange(n) * Ts
    rows = sorted([(t[k], u[k - 1]) for k in range(1, n) if u[k] != u[k - 1]] + list(zip(t, u)),
                  key=lambda row: row[0])  # stable: at a step, the old value comes first
    return Ts, np.array(rows, dtype=[("time", float), ("torque", float)])


class FmusimRule:
    """Patches fmpy so that its CVode restarts after an event only when the FMU asked for it, as fmusim does."""

    def __init__(self, monkeypatch):
        self.restart = False
        rule = self

        class FmusimCVode(fmpy.sundials.CVodeSolver):
            def reset(self, time):
                if rule.restart:
                    super().reset(time)
                rule.restart = False

        def recording(update):
            def wrapper(fmu):
                flags = update(fmu)  # (needed, terminate, nominals changed, values changed, next defined, next)
                rule.restart |= bool(flags[2] or flags[3])
                return flags
            return wrapper

        monkeypatch.setattr(fmpy.sundials, "CVodeSolver", FmusimCVode)
        monkeypatch.setattr(fmpy.fmi2.FMU2Model, "newDiscreteStates", recording(fmpy.fmi2.FMU2Model.newDiscreteStates))
        monkeypatch.setattr(fmpy.fmi3.FMU3Model, "updateDiscreteStates",
                            recording(fmpy.fmi3.FMU3Model.updateDiscreteStates))


def angle(fmu, Ts: float, signal: np.ndarray) -> np.ndarray:
    n = int(round(signal["time"][-1] / Ts)) + 1
    result = fmpy.simulate_fmu(str(fmu), fmi_type="ModelExchange", stop_time=(n - 1) * Ts, output_interval=Ts,
                               input=signal, solver="CVode", relative_tolerance=1e-10)
    return result["angle"]


@pytest.mark.parametrize("version", [2, 3])
def test_fmusim_restart_rule_integrates_input_steps(monkeypatch, version):
    fmu = built_fmu("pendulum", version)
    Ts, signal = torque_steps()
    fmpy_result = angle(fmu, Ts, signal)
    FmusimRule(monkeypatch)
    np.testing.assert_allclose(angle(fmu, Ts, signal), fmpy_result, rtol=1e-9, atol=1e-12)


@pytest.mark.parametrize("version", [2, 3])
def test_values_changed_is_reported_once_per_input_change(version):
    me = MeInstance(built_fmu("pendulum", version), {"angle_start": 0.5})
    update = me.fmu.updateDiscreteStates if me.fmi3 else me.fmu.newDiscreteStates
    x = me.states_now()

    def event(inputs: dict) -> list[bool]:
        me.fmu.enterEventMode()
        me.set(inputs)
        flags = [bool(update()[3]), bool(update()[3])]  # an event iteration of two calls
        me.fmu.enterContinuousTimeMode()
        return flags

    assert event({}) == [False, False]  # an event without a change: no restart
    assert event({"torque": 2.0}) == [True, False]
    assert event({"torque": 2.0}) == [False, False]  # set again to the same value
    assert event({"g_l": 9.0}) == [True, False]  # a tunable parameter
    np.testing.assert_array_equal(me.states_now(), x)  # the states themselves keep their values
    me.fmu.freeInstance()


@pytest.mark.parametrize("version", [2, 3])
def test_model_exchange_range_warning_speaks_of_evaluations(version):
    folder = unzipped(built_fmu("pendulum", version))
    md = fmpy.read_model_description(str(folder))
    messages: list[str] = []
    fmu = instantiate_logged(folder, md, "ModelExchange", lambda *a: messages.append(a[-1].decode()))
    vr = {v.name: v.valueReference for v in md.modelVariables}
    if version == 3:
        fmu.enterInitializationMode(startTime=0.0)
    else:
        fmu.setupExperiment(startTime=0.0)
        fmu.enterInitializationMode()
    fmu.exitInitializationMode()
    (fmu.setFloat64 if version == 3 else fmu.setReal)([vr["torque"]], [2 * TORQUE_RANGE])
    dx = (ctypes.c_double * 2)()
    status = (fmu.getContinuousStateDerivatives if version == 3 else fmu.getDerivatives)(dx, 2)
    assert status == 1  # a Warning
    (message,) = [m for m in messages if "leaves its valid range" in m]
    assert "every evaluation of the derivatives meanwhile returns a warning" in message
    assert "step" not in message  # co-simulation wording
    fmu.freeInstance()
