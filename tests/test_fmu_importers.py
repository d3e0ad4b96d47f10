"""Independent FMI importers run the FMUs too: libcosim (Open Simulation Platform, FMI 2.0 through
FMI Library) and Ecos (FMI 2.0 and 3.0 through fmi4c). Neither shares code with fmpy.

Both are Python packages of the dev extra: ``libcosimpy``, and ``ecospy`` with ``tbb`` (Ecos's
binaries link libtbb.so.12, which the ``tbb`` wheel installs into the environment's lib folder).
"""

from __future__ import annotations

import ctypes
import sys
from pathlib import Path

import numpy as np
import pytest
from fmu_cases import MODELS, built_fmu, excitation


def load_ecospy():
    """Import ecospy after loading the tbb wheel's libtbb.so.12, which its binaries need."""
    candidates = sorted(Path(sys.prefix, "lib").glob("libtbb.so.12*"))
    if not candidates:
        raise RuntimeError("libtbb.so.12 not found in the environment; pip install tbb (dev extra)")
    ctypes.CDLL(str(candidates[0]), mode=ctypes.RTLD_GLOBAL)
    import ecospy

    ecospy.EcosLib.set_log_level("warn")
    return ecospy


def assert_trajectory(got, expected, rtol=1e-9):
    scale = np.abs(expected).max(axis=0)
    np.testing.assert_array_less(np.abs(np.asarray(got) - expected) / scale, rtol)


@pytest.mark.parametrize("name", ["linear", "nonlinear"])
def test_libcosim_runs_the_fmi2_fmu(name):
    from libcosimpy.CosimExecution import CosimExecution
    from libcosimpy.CosimLogging import CosimLogLevel, log_output_level
    from libcosimpy.CosimManipulator import CosimManipulator
    from libcosimpy.CosimObserver import CosimObserver
    from libcosimpy.CosimSlave import CosimLocalSlave

    log_output_level(CosimLogLevel.WARNING)
    model = MODELS[name]
    spec = model.spec
    u, y0 = excitation(model, 60, seed=3), np.array([0.25, -0.5])
    execution = CosimExecution.from_step_size(round(spec.Ts * 1e9))  # libcosim counts nanoseconds
    slave = execution.add_local_slave(CosimLocalSlave(fmu_path=str(built_fmu(name, 2)), instance_name="model"))
    vr = {v.name: v.reference for v in execution.slave_variables(slave)}
    vr = {(k.decode() if isinstance(k, bytes) else k): ref for k, ref in vr.items()}
    for i, v in enumerate(spec.outputs):
        assert execution.real_initial_value(slave, vr[f"{v.name}_start"], float(y0[i]))
    override, observer = CosimManipulator.create_override(), CosimObserver.create_last_value()
    execution.add_manipulator(override)
    execution.add_observer(observer)
    outputs = [vr[v.name] for v in spec.outputs]
    ys = []
    for row in u[:-1]:
        override.slave_real_values(slave, [vr[v.name] for v in spec.inputs], [float(x) for x in row])
        assert execution.step(), "libcosim failed to step the FMU"
        ys.append(observer.last_real_values(slave, outputs))
    assert_trajectory(ys, model.simulate(u, y0)[1:])


@pytest.mark.parametrize("version", [2, 3])
def test_ecos_runs_the_fmu(version):
    ecospy = load_ecospy()
    model = MODELS["nonlinear"]
    spec = model.spec
    u, y0, p = excitation(model, 60, seed=4), np.array([-0.1, 0.3]), np.array([0.8, 0.3])
    structure = ecospy.EcosSimulationStructure()
    structure.add_model("model", str(built_fmu("nonlinear", version)))
    start = {f"model::{v.name}_start": float(y0[i]) for i, v in enumerate(spec.outputs)}
    start.update({f"model::{v.name}": float(p[i]) for i, v in enumerate(spec.parameters)})
    structure.add_parameter_set("start", start)
    with ecospy.EcosSimulation(structure=structure, step_size=spec.Ts) as sim:
        sim.init(parameter_set="start")
        ys = [[sim.get_real(f"model::{v.name}") for v in spec.outputs]]
        for row in u[:-1]:
            for i, v in enumerate(spec.inputs):
                sim.set_real(f"model::{v.name}", float(row[i]))
            sim.step()
            ys.append([sim.get_real(f"model::{v.name}") for v in spec.outputs])
        sim.terminate()
    assert_trajectory(ys, model.simulate(u, y0, p))
