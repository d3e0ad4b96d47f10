"""Model Exchange for continuous-time models: one FMU, both interfaces, CasADi's directional derivatives.

- ``nnfmu physics-fmu valve`` (FMI 2) and an exported hybrid (FMI 3) validate, offer Model Exchange and
  co-simulation, and declare the ModelStructure that CasADi's sparsity gives;
- fmpy's Model Exchange run (CVode) and its co-simulation run (RK4 at Ts) agree on a trajectory with
  held inputs, and CVode agrees with a fine RK4 of the same ODE (so the difference is RK4's own error);
- fmi2/fmi3GetDirectionalDerivative equals central finite differences of the FMU's own derivatives
  and outputs to 1e-6 relative;
- the Model Exchange state machine refuses what FMI forbids, and discrete-time models stay co-simulation;
- the shipped sources (the same templates in every FMU) compile as strict C99 for Windows, as MSVC
  needs, with and without an ODE, and fmpy's CMake route rebuilds a binary that computes the same derivatives.
"""

from __future__ import annotations

import ctypes
import os
import shutil
import xml.etree.ElementTree as ET
import zipfile

import casadi as ca
import fmpy
import numpy as np
import pytest
import torch
from cross_tools import compile_strict_c99
from fmpy.build import build_platform_binary
from fmpy.validation import validate_fmu
from fmu_cases import FMICallException, built_fmu, unzipped

from nnfmu.cli import main as nnfmu_main
from nnfmu.export import build_fmu, casadi_model
from nnfmu.hybrid import HybridConfig, HybridStepModel
from nnfmu.physics import rk4_function, valve_system
from nnfmu.system import CasadiModel, ContinuousDynamics, SystemSpec, Variable

#: fmpy's CVode (relative tolerance 1e-10) against the FMU's RK4 (4 sub-steps of 10 us), as a fraction of
#: each output's range over the test trajectory: RK4's discretisation error of the valve (measured 4e-5).
ME_CS_TOLERANCE = 1e-4

pytestmark = pytest.mark.usefixtures("one_thread")


@pytest.fixture(scope="module")
def valve_fmu(tmp_path_factory):
    out = tmp_path_factory.mktemp("me") / "v.fmu"
    assert nnfmu_main(["physics-fmu", "valve", "-o", str(out)]) == 0
    return out


def _hybrid(n_sub: int | None = None) -> HybridStepModel:
    """An untrained valve hybrid with a random (nonzero) derivative correction and valve-sized inputs."""
    torch.manual_seed(0)
    model = HybridStepModel(HybridConfig(n_u=2, n_y=2, physics="valve", hidden=8, n_sub=n_sub)).double().eval()
    generator = torch.Generator().manual_seed(1)
    with torch.no_grad():
        for prm in model.correction.parameters():
            prm.copy_(0.1 * torch.randn(prm.shape, generator=generator))
        model.u_mean.fill_(100.0), model.u_std.fill_(60.0)
    return model


@pytest.fixture(scope="module")
def hybrid_fmu(tmp_path_factory):
    model = casadi_model(_hybrid(), name="valve_hybrid")
    assert model.continuous is not None
    return model, build_fmu(model, tmp_path_factory.mktemp("me") / "hybrid.fmu", fmi_version=3)


def held_inputs(n: int, hold: int = 25, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """Piecewise-constant valve voltages (n, 2) and fmpy's input signal with a step (an event) at each change."""
    rng = np.random.default_rng(seed)
    u = np.repeat(rng.uniform(0.0, 200.0, size=(n // hold + 1, 2)), hold, axis=0)[:n]
    t = np.arange(n) * valve_system().Ts
    rows = [(t[k], *u[k - 1]) for k in range(1, n) if np.any(u[k] != u[k - 1])] + list(zip(t, *u.T))
    rows.sort(key=lambda row: row[0])  # stable: at a step, the old value comes first
    return u, np.array(rows, dtype=[("time", float), ("u1", float), ("u2", float)])


def simulate(fmu, fmi_type: str, signal, n: int, y0, **options) -> np.ndarray:
    """fmpy's result (s, p) at the sample instants 0 .. n-1 (after any event there)."""
    Ts = valve_system().Ts
    result = fmpy.simulate_fmu(str(fmu), fmi_type=fmi_type, stop_time=(n - 1) * Ts, output_interval=Ts,
                               input=signal, start_values={"s_start": y0[0], "p_start": y0[1]}, **options)
    rows = [np.flatnonzero(np.abs(result["time"] - k * Ts) < 1e-6 * Ts)[-1] for k in range(n)]
    return np.column_stack([result["s"], result["p"]])[rows]


@pytest.mark.parametrize("which", ["valve", "hybrid"])
def test_fmu_offers_both_interfaces_and_validates(valve_fmu, hybrid_fmu, which):
    fmu = valve_fmu if which == "valve" else hybrid_fmu[1]
    assert validate_fmu(str(fmu)) == []
    md = fmpy.read_model_description(str(fmu))
    assert md.modelExchange.modelIdentifier == md.coSimulation.modelIdentifier
    root = ET.fromstring(zipfile.ZipFile(fmu).read("modelDescription.xml"))
    provides = "providesDirectionalDerivative" + ("s" if md.fmiVersion.startswith("3") else "")
    assert (root.find("ModelExchange").get(provides), root.find("CoSimulation").get(provides)) == ("true", "false")
    assert [v.name for v in md.modelVariables if v.causality == "output"] == ["s", "p"]
    assert all(v.variability == "continuous" for v in md.modelVariables if v.causality == "output")
    assert [d.variable.name for d in md.derivatives] == [f"der(x.{v.name})" for v in valve_system().states]


def test_model_structure_is_casadi_sparsity(valve_fmu):
    md = fmpy.read_model_description(str(valve_fmu))
    deps = {u.variable.name: sorted(d.name for d in u.dependencies)
            for u in [*md.outputs, *md.derivatives]}
    assert deps["s"] == ["x.s"] and deps["p"] == ["x.p"]  # y = (s, p): no feedthrough, one state each
    assert deps["der(x.z1)"] == ["x.z1dot"]  # kinematics
    assert deps["der(x.z1dot)"] == ["u1", "x.z1", "x.z1dot"]  # the bender: its voltage and its own state
    assert deps["der(x.s)"] == ["x.sdot"]
    assert "u2" not in deps["der(x.z1dot)"] and "u1" not in deps["der(x.p)"]  # u acts through the benders only
    initial = {u.variable.name: sorted(d.name for d in u.dependencies) for u in md.initialUnknowns}
    assert initial["s"] == ["s_start"] and initial["x.z1"] == ["d_u", "u1"]  # z1(0) = d_u * u1(0)


def test_model_exchange_matches_co_simulation_and_the_exact_ode(valve_fmu):
    n, y0 = 500, np.array([0.0, 2.0e5])
    u, signal = held_inputs(n)
    cs = simulate(valve_fmu, "CoSimulation", signal, n, y0)
    me = simulate(valve_fmu, "ModelExchange", signal, n, y0, solver="CVode", relative_tolerance=1e-10)
    scale = np.ptp(cs, axis=0)
    assert scale.min() > 0, "the inputs must move the valve"
    assert np.max(np.abs(cs - valve_system().model().simulate(u, y0)) / scale) < 1e-10
    assert_model_exchange_is_the_ode(me, cs, valve_system().model(n_sub=16).simulate(u, y0))


def assert_model_exchange_is_the_ode(me: np.ndarray, cs: np.ndarray, fine: np.ndarray) -> None:
    """ME within the tolerance of CS, and the difference is RK4's error: RK4 with 16 sub-steps (its error
    divided by 256) agrees with CVode far better than the FMU's 4."""
    scale = np.ptp(cs, axis=0)
    difference = np.max(np.abs(me - cs) / scale)
    assert difference < ME_CS_TOLERANCE
    assert np.max(np.abs(me - fine) / scale) < 0.05 * difference


def test_hybrid_model_exchange_matches_its_co_simulation(hybrid_fmu):
    model, fmu = hybrid_fmu
    n, y0 = 300, np.array([1e-4, 3.0e5])
    u, signal = held_inputs(n, seed=1)
    cs = simulate(fmu, "CoSimulation", signal, n, y0)
    me = simulate(fmu, "ModelExchange", signal, n, y0, solver="CVode", relative_tolerance=1e-10)
    np.testing.assert_allclose(cs, model.simulate(u, y0), rtol=1e-10, atol=0)
    assert_model_exchange_is_the_ode(me, cs, casadi_model(_hybrid(n_sub=16)).simulate(u, y0))


class MeInstance:
    """A Model Exchange instance in continuous-time mode, through fmpy, the same for FMI 2 and 3."""

    def __init__(self, fmu, start: dict):
        folder = unzipped(fmu) if fmu.suffix == ".fmu" else fmu  # or an unzipped FMU
        self.md = fmpy.read_model_description(str(folder))
        self.fmi3 = self.md.fmiVersion.startswith("3")
        self.vr = {v.name: v.valueReference for v in self.md.modelVariables}
        self.states = [d.variable.derivative.name for d in self.md.derivatives]
        self.fmu = fmpy.instantiate_fmu(str(folder), self.md, "ModelExchange")
        if self.fmi3:
            self.fmu.enterInitializationMode(startTime=0.0)
        else:
            self.fmu.setupExperiment(startTime=0.0)
            self.fmu.enterInitializationMode()
        self.set(start)
        self.fmu.exitInitializationMode()
        (self.fmu.updateDiscreteStates if self.fmi3 else self.fmu.newDiscreteStates)()
        self.fmu.enterContinuousTimeMode()

    def set(self, values: dict) -> None:
        (self.fmu.setFloat64 if self.fmi3 else self.fmu.setReal)([self.vr[k] for k in values], list(values.values()))

    def get(self, names) -> np.ndarray:
        return np.array((self.fmu.getFloat64 if self.fmi3 else self.fmu.getReal)([self.vr[k] for k in names]))

    def derivatives(self) -> tuple[int, np.ndarray]:
        """(status, der(x)) of getDerivatives / getContinuousStateDerivatives."""
        dx = np.zeros(len(self.states))
        status = self.fmu.getDerivatives(dx.ctypes.data_as(ctypes.POINTER(ctypes.c_double)), dx.size) if not self.fmi3 \
            else self.fmu.getContinuousStateDerivatives(dx.ctypes.data_as(ctypes.POINTER(ctypes.c_double)), dx.size)
        return status, dx

    def set_states(self, x: np.ndarray) -> None:
        x = np.ascontiguousarray(x, dtype=float)
        self.fmu.setContinuousStates(x.ctypes.data_as(ctypes.POINTER(ctypes.c_double)), x.size)

    def states_now(self) -> np.ndarray:
        x = np.zeros(len(self.states))
        self.fmu.getContinuousStates(x.ctypes.data_as(ctypes.POINTER(ctypes.c_double)), x.size)
        return x

    def jacobian(self, unknowns, knowns) -> np.ndarray:
        refs = [self.vr[k] for k in unknowns]
        return np.column_stack([self.fmu.getDirectionalDerivative(refs, [self.vr[k]], [1.0]) for k in knowns])

    def finite_differences(self, unknowns, inputs: dict, floor: float) -> np.ndarray:
        """Central differences of ``unknowns`` over the states, then ``inputs`` (name -> value), at the current
        states and those inputs: the columns of :meth:`jacobian` with knowns ``[*states, *inputs]``. The step of
        an entry z is ``1e-6 max(|z|, floor)``; the states and inputs are left at the point."""
        point = np.concatenate([self.states_now(), list(inputs.values())])
        n_x = point.size - len(inputs)

        def unknowns_at(z):
            self.set_states(z[:n_x])
            self.set(dict(zip(inputs, z[n_x:])))
            return self.get(unknowns)

        fd = np.zeros((len(unknowns), point.size))
        for j in range(point.size):
            h = 1e-6 * max(abs(point[j]), floor)
            plus, minus = point.copy(), point.copy()
            plus[j] += h
            minus[j] -= h
            fd[:, j] = (unknowns_at(plus) - unknowns_at(minus)) / (2 * h)
        unknowns_at(point)
        return fd


@pytest.mark.parametrize("which", ["valve", "hybrid"])
def test_directional_derivatives_equal_finite_differences(valve_fmu, hybrid_fmu, which):
    fmu = valve_fmu if which == "valve" else hybrid_fmu[1]
    me = MeInstance(fmu, {"s_start": 3e-4, "p_start": 4.0e5})
    me.set({"u1": 120.0, "u2": 80.0})
    x = me.states_now() + np.array([2e-6, 1e-3, 5e-6, -2e-3, 1e3, 1e-4, 1e-2])  # off the rest state
    me.set_states(x)
    unknowns = [f"der({s})" for s in me.states] + ["s", "p"]
    knowns = [*me.states, "u1", "u2"]
    jacobian = me.jacobian(unknowns, knowns)
    fd = me.finite_differences(unknowns, {"u1": 120.0, "u2": 80.0}, floor=1e-5)
    scale = np.abs(jacobian).max(axis=1, keepdims=True)  # per unknown: relative to its largest sensitivity
    np.testing.assert_array_less(np.abs(jacobian - fd) / scale, 1e-6)
    declared = {(u.variable.name, d.name) for u in [*me.md.derivatives, *me.md.outputs] for d in u.dependencies}
    nonzero = {(unknowns[i], knowns[j]) for i, j in zip(*np.nonzero(jacobian))}
    assert len(nonzero) >= 19 and nonzero <= declared  # the ModelStructure covers every sensitivity
    me.fmu.terminate()
    me.fmu.freeInstance()


@pytest.mark.parametrize("which", ["valve", "hybrid"])
def test_input_outside_its_range_is_a_warning_in_model_exchange(valve_fmu, hybrid_fmu, which):
    me = MeInstance(valve_fmu if which == "valve" else hybrid_fmu[1], {"p_start": 3e5})
    assert me.derivatives()[0] == 0
    maximum = next(v for v in me.md.modelVariables if v.name == "u1").max
    me.set({"u1": float(maximum) + 1.0})
    status, dx = me.derivatives()
    assert status == 1 and np.isfinite(dx).all()  # fmi2Warning / fmi3Warning, and the derivatives
    me.fmu.enterEventMode()
    me.fmu.setBoolean([me.vr["input_range_error"]], [True])
    me.fmu.enterContinuousTimeMode()
    with pytest.raises(FMICallException):
        me.derivatives()
    me.fmu.freeInstance()


def test_model_exchange_state_machine(valve_fmu):
    me = MeInstance(valve_fmu, {"p_start": 3e5})
    with pytest.raises(FMICallException):
        me.set({"k_s": 2e4})  # a parameter in continuous-time mode
    me.fmu.freeInstance()
    me = MeInstance(valve_fmu, {"p_start": 3e5})
    with pytest.raises(FMICallException):
        me.set({"x.p": 1e5})  # states are set with setContinuousStates
    me.fmu.freeInstance()
    cs = fmpy.instantiate_fmu(str(unzipped(valve_fmu)), me.md, "CoSimulation")
    cs.setupExperiment(startTime=0.0)
    cs.enterInitializationMode()
    cs.setReal([me.vr["p_start"]], [3e5])
    cs.exitInitializationMode()
    assert cs.getReal([me.vr["x.p"]]) == [3e5]  # the co-simulation state is readable too (x0 from p_start)
    with pytest.raises(FMICallException):
        cs.getDirectionalDerivative([me.vr["der(x.p)"]], [me.vr["x.p"]], [1.0])
    cs.freeInstance()


@pytest.mark.parametrize("name", ["linear", "valve_gru"])
def test_discrete_time_models_stay_co_simulation(name):
    md = fmpy.read_model_description(str(built_fmu(name, 2)))
    assert md.modelExchange is None and md.coSimulation is not None and not md.derivatives


@pytest.mark.parametrize("which", ["valve", "hybrid", "linear"])
def test_sources_are_strict_c99_for_windows(valve_fmu, hybrid_fmu, which, tmp_path):
    fmu = {"valve": valve_fmu, "hybrid": hybrid_fmu[1]}.get(which) or built_fmu("linear", 2)  # linear: no ODE
    md = fmpy.read_model_description(str(unzipped(fmu)))
    files = md.buildConfigurations[0].sourceFileSets[0].sourceFiles
    assert {"nnfmu_me.c", "nnfmu_me_model.c", f"nnfmu_fmi{md.fmiVersion[0]}_me.c"} <= set(files)
    compile_strict_c99(unzipped(fmu) / "sources", files, tmp_path)


def pendulum() -> CasadiModel:
    """A damped pendulum, ``angle'' = -g_l sin(angle) - damping angle' + torque``: a small continuous-time model."""
    x, u, p, y0 = ca.SX.sym("x", 2), ca.SX.sym("u"), ca.SX.sym("p", 2), ca.SX.sym("y0")
    ode = ca.Function("ode", [x, u, p], [ca.vertcat(x[1], -p[0] * ca.sin(x[0]) - p[1] * x[1] + u)],
                      ["x", "u", "p"], ["xdot"])
    output = ca.Function("output", [x, p], [x[0]], ["x", "p"], ["y"])
    x_next = rk4_function(ode, Ts=0.01, n_sub=2)(x, u, p)
    step = ca.Function("step", [x, u, p], [x_next, output(x_next, p)], ["x", "u", "p"], ["x_next", "y_next"])
    init = ca.Function("init", [y0, u, p], [ca.vertcat(y0, 0)], ["y0", "u0", "p"], ["x0"])
    spec = SystemSpec("pendulum", 0.01, [Variable("torque", "1/s2")], [Variable("angle", "rad", start=0.5)],
                      [Variable("g_l", "1/s2", start=9.81), Variable("damping", "1/s", start=0.3)])
    states = [Variable("angle", "rad"), Variable("rate", "rad/s")]
    return CasadiModel(init, step, spec, continuous=ContinuousDynamics(ode, output, states))


def test_fmpy_cmake_rebuilds_a_model_exchange_fmu(tmp_path):
    fmu = build_fmu(pendulum(), tmp_path / "pendulum.fmu")
    assert validate_fmu(str(fmu)) == []
    folder = tmp_path / "rebuilt"
    shutil.copytree(unzipped(fmu), folder)
    shutil.rmtree(folder / "binaries")
    (tmp_path / "build").mkdir()
    build_platform_binary(os.path.abspath(folder), build_dir=os.path.abspath(tmp_path / "build"))
    instances = [MeInstance(f, {"angle_start": 1.0}) for f in (fmu, folder)]
    for instance in instances:
        instance.set({"torque": 0.5})
    derivatives = [f"der({s})" for s in instances[0].states]
    jacobians = [i.jacobian(derivatives, ["x.angle", "x.rate", "torque"]) for i in instances]
    np.testing.assert_array_equal(jacobians[0], [[0.0, 1.0, 0.0], [-9.81 * np.cos(1.0), -0.3, 1.0]])
    np.testing.assert_array_equal(*jacobians)
    np.testing.assert_array_equal(*(i.get(derivatives) for i in instances))
    for instance in instances:
        instance.fmu.freeInstance()
