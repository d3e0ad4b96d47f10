"""One C framework for both interfaces, shaped like the FMI Reference FMUs (docs/design.md, the C core).

- every FMU of an FMI version ships and compiles the same template files, whether its model has an ODE
  (Model Exchange and co-simulation) or not (co-simulation only): only the generated code differs, and
  no template switches code on or off with the preprocessor by interface or ODE;
- an FMU whose model has no ODE refuses Model Exchange at instantiation with one logged line that says
  why, and the Model Exchange entry points it exports like every FMU return an Error that says why.
"""

from __future__ import annotations

import ctypes
import re
from pathlib import Path

import casadi as ca
import fmpy
import pytest
from fmpy.fmi2 import FMU2Model, fmi2CallbackFunctions, fmi2CallbackLoggerTYPE
from fmpy.fmi3 import FMU3Model
from fmu_cases import built_fmu, instantiate_logged, unzipped

import nnfmu.export
from nnfmu.export import build_fmu
from nnfmu.physics import rk4_function
from nnfmu.system import CasadiModel, ContinuousDynamics, SystemSpec, Variable

TEMPLATES = Path(nnfmu.export.__file__).parent / "templates"
GENERATED = {"model_casadi.c", "model_casadi.h", "model_me_casadi.c", "model_me_casadi.h", "nnfmu_model.h",
             "buildDescription.xml"}
NO_ODE = "this FMU is for co-simulation only"
_KEEP_ALIVE: list = []  # callbacks an FMU may have kept a pointer to


def decay() -> CasadiModel:
    """``x' = -k x + u``, ``y = x``: the smallest model with an ODE (Model Exchange and co-simulation)."""
    x, u, p, y0 = ca.SX.sym("x"), ca.SX.sym("u"), ca.SX.sym("p"), ca.SX.sym("y0")
    ode = ca.Function("ode", [x, u, p], [-p * x + u], ["x", "u", "p"], ["xdot"])
    output = ca.Function("output", [x, p], [x], ["x", "p"], ["y"])
    x_next = rk4_function(ode, Ts=0.1, n_sub=1)(x, u, p)
    step = ca.Function("step", [x, u, p], [x_next, x_next], ["x", "u", "p"], ["x_next", "y_next"])
    init = ca.Function("init", [y0, u, p], [y0], ["y0", "u0", "p"], ["x0"])
    spec = SystemSpec("decay", 0.1, [Variable("u", "1")], [Variable("y", "1")], [Variable("k", "1/s", start=2.0)])
    return CasadiModel(init, step, spec, continuous=ContinuousDynamics(ode, output, [Variable("y", "1")]))


def _listed(folder: Path) -> list[str]:
    return fmpy.read_model_description(str(folder)).buildConfigurations[0].sourceFileSets[0].sourceFiles


@pytest.mark.parametrize("version", [2, 3])
def test_every_fmu_ships_and_compiles_the_same_templates(version, tmp_path):
    cs = unzipped(built_fmu("linear", version))
    me = unzipped(build_fmu(decay(), tmp_path / "decay.fmu", fmi_version=version))
    assert fmpy.read_model_description(str(me)).modelExchange is not None
    assert _listed(cs) == _listed(me)
    files = [{p.name for p in (folder / "sources").iterdir()} for folder in (cs, me)]
    assert files[1] - files[0] == {"model_me_casadi.h"} and files[0] <= files[1]  # CasADi's header of the ODE
    for name in files[0] - GENERATED:  # the templates and FMI headers, byte for byte
        assert (cs / "sources" / name).read_bytes() == (me / "sources" / name).read_bytes(), name
    for template in TEMPLATES.iterdir():
        switched = re.findall(r"^\s*#\s*if.*\b(\w*(?:MODEL_EXCHANGE|HAS_ODE)\w*)", template.read_text(), re.M)
        assert switched == [], f"{template.name} switches code by interface with the preprocessor"


def _model_exchange_instance(folder: Path, version: int, log):
    """Ask the FMU in ``folder`` for a Model Exchange instance although it declares co-simulation only."""
    md = fmpy.read_model_description(str(folder))
    assert md.modelExchange is None
    kwargs = dict(guid=md.guid, unzipDirectory=str(folder), modelIdentifier=md.coSimulation.modelIdentifier,
                  instanceName="me")
    if version == 2:  # fmpy's own FMI 2 logger goes through a global proxy: pass plain callbacks instead
        callbacks = fmi2CallbackFunctions()
        callbacks.logger = fmi2CallbackLoggerTYPE(lambda env, name, status, category, message: log(message))
        _KEEP_ALIVE.append(callbacks)
        return FMU2Model(**kwargs).instantiate(callbacks=callbacks)
    fmu = FMU3Model(**kwargs)
    _KEEP_ALIVE.append(fmu)
    return fmu.instantiate(logMessage=lambda env, status, category, message: log(message))


@pytest.mark.parametrize("version", [2, 3])
def test_an_fmu_without_an_ode_refuses_model_exchange_and_says_why(version):
    folder = unzipped(built_fmu("linear", version))
    messages: list[str] = []
    with pytest.raises(Exception, match="Failed to instantiate"):
        _model_exchange_instance(folder, version, lambda message: messages.append(message.decode()))
    caller = "fmi2Instantiate" if version == 2 else "fmi3InstantiateModelExchange"
    assert messages == [f"{caller}: {NO_ODE}: its model has no ODE for Model Exchange"]


@pytest.mark.parametrize("version", [2, 3])
def test_model_exchange_calls_without_an_ode_are_errors_that_say_why(version):
    folder = unzipped(built_fmu("linear", version))
    md = fmpy.read_model_description(str(folder))
    messages: list[str] = []
    cs = instantiate_logged(folder, md, "CoSimulation", lambda *a: messages.append(a[-1].decode()))
    if version == 2:
        cs.setupExperiment(startTime=0.0)
    cs.enterInitializationMode()
    cs.exitInitializationMode()
    get_states = getattr(cs.dll, f"fmi{version}GetContinuousStates")
    get_states.argtypes = [ctypes.c_void_p, ctypes.POINTER(ctypes.c_double), ctypes.c_size_t]
    get_states.restype = ctypes.c_int
    assert get_states(cs.component, None, 0) == 3  # fmi2Error / fmi3Error
    assert messages[-1] == (f"fmi{version}GetContinuousStates is not supported: {NO_ODE} (its model has no ODE "
                            f"for Model Exchange)")
    cs.freeInstance()
