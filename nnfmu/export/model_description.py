"""One description of an FMU's variables, rendered into modelDescription.xml (FMI 2 and 3).

Value references are assigned once, in :func:`describe`, and every artefact
that names a variable (the XML for FMI 2.0 or 3.0, FMI 3's
``buildDescription.xml`` and the wrapper's ``nnfmu_model.h``, see
:mod:`nnfmu.export.c_header`) is rendered from that one :class:`FmuDescription`.
The layout is::

    vr 0                     time                  independent
    vr 1                     Ts                    local constant, the sample time in s
    vr 2                     max_samples_per_step  parameter, tunable, Integer: the most samples one doStep takes
    vr 3                     input_range_error     parameter, tunable, Boolean: out-of-range inputs are an error
    vr 4 ...                 inputs                input, continuous (held over each sample), with min/max
    then                     outputs               output, discrete (they change at sample times only)
    then                     <y>_start             parameter, fixed: the initial outputs y0
    then                     parameters            parameter, tunable: the ``p`` port
    then                     <c>_past              parameter, fixed: the init window (``spec.init_window > 1``)
    then (Model Exchange)    x.<state>, der(...)   local, continuous: the ODE's states, then their derivatives

A model whose ``init`` sees an init window of ``N`` samples (:mod:`nnfmu.window_names`) takes
the ``N - 1`` samples before t0 of every output and input: FMI 3 one array ``<c>_past`` of
``N - 1`` values per channel, FMI 2 one scalar ``<c>_past[j]`` per sample (``j = 1`` the
oldest). Their start value is NaN, meaning "not set": the FMU then uses ``y0`` (the
``<y>_start`` value) or the first input ``u0`` there, the plant at rest.

The outputs at t0 are the ``<y>_start`` values, so they are initial unknowns
that depend on those parameters only; outputs never depend directly on inputs
(no feedthrough). A continuous-time model's FMU also offers Model Exchange
(:class:`ContinuousStructure`, built by :mod:`nnfmu.export.model_exchange`): then
its outputs are continuous functions of the states, and the ModelStructure lists
the dependencies of outputs and derivatives from the CasADi sparsity pattern. The
FMU's behaviour is described in docs/fmu.md and docs/fmu-platforms.md.
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from dataclasses import dataclass

from nnfmu import __version__
from nnfmu.errors import FmuBuildError
from nnfmu.identifiers import is_c_identifier
from nnfmu.limits import MAX_MODEL_NAME
from nnfmu.system import SystemSpec, Variable
from nnfmu.window_names import past_element, past_name

GENERATION_TOOL = f"nnfmu {__version__}"
LOG_CATEGORIES = (("logStatusError", "errors: bad calls, calls not allowed in the current state, non-finite values"),
                  ("logStatusWarning", "warnings: an input leaves its valid range [min, max]"))
#: Default of the parameter max_samples_per_step: a doStep needing more samples is refused at once.
MAX_SAMPLES_PER_STEP = 10_000_000
RESERVED_NAMES = ("time", "Ts", "max_samples_per_step", "input_range_error")
STEPPING_RULE = ("doStep(t, h) accepts any h > 0 and advances every sample instant t0 + k*Ts in (t, t+h] with the "
                 "inputs held; the outputs are those of the last sample reached. Inputs outside [min, max] give "
                 "a warning (input_range_error = true: an error)")


@dataclass(frozen=True)
class ScalarVariable:
    """One scalar of the FMU; ``role`` and ``index`` tie it to the C side (e.g. role 'input', index 1 = u[1])."""

    name: str
    value_reference: int
    causality: str
    variability: str
    initial: str | None
    start: float | None
    unit: str
    description: str
    role: str
    index: int = 0
    type: str = "Real"  # Real, Integer or Boolean
    min: float | None = None
    max: float | None = None
    size: int = 1  # values of the variable: > 1 for an FMI 3 array (one Dimension)
    nominal: float | None = None
    derivative: int | None = None  # a state derivative: the value reference of its state


#: A variable of the description by role and index, e.g. ("state", 2) or ("input", 0).
Slot = tuple[str, int]


@dataclass(frozen=True)
class ContinuousStructure:
    """The Model Exchange side of an FMU: its continuous states and what each unknown depends on.

    ``outputs[i]`` are the knowns output i depends on (states), ``derivatives[j]`` those of
    ``der(x_j)`` (states and inputs), ``initial`` maps each initial unknown (outputs, states,
    derivatives) to the knowns it depends on at initialization (``output_start``, inputs, parameters).
    """

    states: tuple[Variable, ...]
    nominals: tuple[float, ...]
    outputs: tuple[tuple[Slot, ...], ...]
    derivatives: tuple[tuple[Slot, ...], ...]
    initial: tuple[tuple[Slot, tuple[Slot, ...]], ...]


@dataclass(frozen=True)
class FmuDescription:
    """Everything that names a variable or identifies the FMU; rendered by this module and c_header."""

    spec: SystemSpec
    variables: tuple[ScalarVariable, ...]
    model_identifier: str
    token: str
    generation_time: str
    structure: ContinuousStructure | None = None

    def by_role(self, role: str) -> tuple[ScalarVariable, ...]:
        return tuple(v for v in self.variables if v.role == role)

    def dependencies(self, kind: str) -> list[tuple[ScalarVariable, tuple[int, ...]]]:
        """``(unknown, value references of its knowns)`` for kind 'output', 'derivative' or 'initial', by vr."""
        vr = {(v.role, v.index): v.value_reference for v in self.variables}
        if self.structure is None:  # co-simulation only: outputs depend on their start values at t0 only
            starts = [(v, (vr[("output_start", v.index)],)) for v in self.by_role("output")]
            return {"output": [(v, ()) for v in self.by_role("output")], "derivative": [], "initial": starts}[kind]
        s = self.structure
        pairs = {"output": zip(self.by_role("output"), s.outputs, strict=True),
                 "derivative": zip(self.by_role("derivative"), s.derivatives, strict=True),
                 "initial": ((self.variables[vr[slot]], knowns) for slot, knowns in s.initial)}[kind]
        per_past = max((v.size for v in self.by_role("past")), default=1)  # FMI 3: one array per channel
        ref = lambda k: vr[("past", k[1] // per_past) if k[0] == "past" else k]  # noqa: E731
        return sorted(((v, tuple(sorted({ref(k) for k in knowns}))) for v, knowns in pairs),
                      key=lambda pair: pair[0].value_reference)

    @property
    def units(self) -> list[str]:
        return sorted({v.unit for v in self.variables if v.unit})

    @property
    def description(self) -> str:
        spec = self.spec
        head = spec.description or f"{spec.name}: discrete-time model"
        me = (" Model Exchange: the ODE xdot = f(x, u, p) and y = g(x, p), with directional derivatives."
              if self.structure else "")
        return f"{head}; Ts = {spec.Ts:g} s. {STEPPING_RULE}.{me}"


def check_spec(spec: SystemSpec) -> None:
    """Raise FmuBuildError if ``spec`` cannot become an FMU (C identifier, finite starts, names, ranges)."""
    if not is_c_identifier(spec.name):
        raise FmuBuildError(
            f"the model name {spec.name!r} becomes the FMU's modelIdentifier and must be an ASCII C "
            f"identifier; rename it (letters a-z, A-Z, digits, '_')")
    if len(spec.name) > MAX_MODEL_NAME:
        raise FmuBuildError(f"the model name has {len(spec.name)} characters, above nnfmu's limit of {MAX_MODEL_NAME} "
                            "(nnfmu.limits.MAX_MODEL_NAME): it names the FMU's files; choose a shorter name")
    for v in spec.inputs + spec.outputs + spec.parameters:
        if not math.isfinite(v.start):
            raise FmuBuildError(f"the start value of {v.name!r} is {v.start!r}; give it a finite start value")
        if v.name in RESERVED_NAMES:
            raise FmuBuildError(f"the variable name {v.name!r} is taken by the FMU itself "
                                f"({', '.join(RESERVED_NAMES)}); rename the variable")
    for v in spec.inputs:
        if (v.min is not None and v.start < v.min) or (v.max is not None and v.start > v.max):
            raise FmuBuildError(f"the start value {v.start!r} of input {v.name!r} lies outside its range "
                                f"[{v.min}, {v.max}]; give it a start value inside")


def _window_rows(spec: SystemSpec, fmi_version: int) -> list[dict]:
    """The init window's parameters: per channel an FMI 3 array, or FMI 2 scalars, of the N - 1 samples before t0."""
    n_past = spec.init_window - 1
    rows = []
    for c, v in enumerate(spec.outputs + spec.inputs):
        what = "output" if c < spec.n_y else "input"
        rest = f"{v.name}_start" if what == "output" else f"the first input {v.name}"
        text = (f"init window: {v.name} at the {n_past} samples before the start time, oldest first; NaN (the "
                f"default): not set, {rest} is used there (the plant at rest)")
        common = dict(causality="parameter", variability="fixed", initial="exact", start=math.nan, unit=v.unit,
                      role="past", description=text)
        if fmi_version == 3:
            rows.append(dict(name=past_name(v.name), size=n_past, index=c, **common))
        else:
            rows += [dict(name=past_element(v.name, j + 1), index=c * n_past + j, **common) for j in range(n_past)]
    return rows


def describe(spec: SystemSpec, token: str, generation_time: str, fmi_version: int = 2, *,
             structure: ContinuousStructure | None = None) -> FmuDescription:
    """Assign value references (see the module docstring) and return the one description of the FMU.

    ``structure``: the Model Exchange side of a continuous-time model (states, dependencies), or None.
    """
    check_spec(spec)
    rows = [
        dict(name="time", causality="independent", variability="continuous", unit="s",
             description="simulation time", role="time"),
        dict(name="Ts", causality="local", variability="constant", initial="exact", start=spec.Ts, unit="s",
             description="sample time of the discrete-time model", role="Ts"),
        dict(name="max_samples_per_step", causality="parameter", variability="tunable", initial="exact",
             start=MAX_SAMPLES_PER_STEP, type="Integer", min=1, role="max_samples",
             description="the most samples one doStep may take; a longer step is refused at once"),
        dict(name="input_range_error", causality="parameter", variability="tunable", initial="exact", start=0,
             type="Boolean", role="range_error",
             description="true: an input outside its [min, max] is an error and the step is not taken; "
                         "false: the step is taken and returns a warning"),
    ]
    rows += [dict(name=v.name, causality="input", variability="continuous", start=v.start, unit=v.unit,
                  description=v.description, role="input", index=i, min=v.min, max=v.max)
             for i, v in enumerate(spec.inputs)]
    rows += [dict(name=v.name, causality="output", variability="continuous" if structure else "discrete",
                  initial="calculated", unit=v.unit, description=v.description, role="output", index=i)
             for i, v in enumerate(spec.outputs)]
    rows += [dict(name=f"{v.name}_start", causality="parameter", variability="fixed", initial="exact",
                  start=v.start, unit=v.unit, role="output_start", index=i,
                  description=f"initial value y0 of output {v.name} (the output at the start time)")
             for i, v in enumerate(spec.outputs)]
    rows += [dict(name=v.name, causality="parameter", variability="tunable", initial="exact", start=v.start,
                  unit=v.unit, description=v.description, role="parameter", index=i)
             for i, v in enumerate(spec.parameters)]
    rows += _window_rows(spec, fmi_version) if spec.init_window > 1 else []
    if structure is not None:
        rows += _state_rows(structure, first_vr=len(rows))
    defaults = dict(initial=None, start=None, unit="", description="", index=0)
    variables = tuple(ScalarVariable(value_reference=vr, **{**defaults, **row}) for vr, row in enumerate(rows))
    return FmuDescription(spec, variables, spec.name, token, generation_time, structure)


def _state_rows(structure: ContinuousStructure, first_vr: int) -> list[dict]:
    """The continuous states ``x.<name>`` (value references from ``first_vr``), then their derivatives
    ``der(x.<name>)``: the prefix keeps them apart from inputs, outputs and parameters of the same name."""
    states = structure.states
    rows = [dict(name=f"x.{v.name}", causality="local", variability="continuous", initial="calculated", unit=v.unit,
                 description=f"continuous state: {v.description}".rstrip(": "), role="state", index=i, nominal=n)
            for i, (v, n) in enumerate(zip(states, structure.nominals, strict=True))]
    rows += [dict(name=f"der(x.{v.name})", causality="local", variability="continuous", initial="calculated",
                  unit=f"{v.unit or '1'}/s", description=f"time derivative of x.{v.name}", role="derivative",
                  index=i, derivative=first_vr + i) for i, v in enumerate(states)]
    return rows


def num(x: float) -> str:
    """Shortest round-trip decimal of a float, valid in XML and as a C double literal."""
    text = repr(float(x))
    return text if any(c in text for c in ".en") else text + ".0"


def _start_text(v: ScalarVariable) -> str | None:
    if v.start is None:
        return None
    if v.type == "Boolean":
        return "true" if v.start else "false"
    if v.type == "Integer":
        return str(int(v.start))
    one = "NaN" if math.isnan(v.start) else num(v.start)  # xs:double spells it NaN
    return " ".join([one] * v.size)


def _bound_text(v: ScalarVariable, bound: float | None) -> str | None:
    if bound is None:
        return None
    return str(int(bound)) if v.type == "Integer" else num(bound)


def _value_attrs(v: ScalarVariable) -> dict[str, str]:
    return _attrs(start=_start_text(v), min=_bound_text(v, v.min), max=_bound_text(v, v.max), unit=v.unit,
                  nominal=_bound_text(v, v.nominal))


def _to_text(root: ET.Element) -> str:
    ET.indent(root, space="  ")
    return '<?xml version="1.0" encoding="UTF-8"?>\n' + ET.tostring(root, encoding="unicode") + "\n"


def _attrs(**kw) -> dict[str, str]:
    return {k: v for k, v in kw.items() if v not in (None, "")}


def _header_attrs(desc: FmuDescription, fmi_version: str) -> dict[str, str]:
    token_key = "guid" if fmi_version == "2.0" else "instantiationToken"
    return _attrs(fmiVersion=fmi_version, modelName=desc.spec.name, **{token_key: desc.token},
                  description=desc.description, generationTool=GENERATION_TOOL,
                  generationDateAndTime=desc.generation_time, variableNamingConvention="flat")


def _units_and_experiment(root: ET.Element, desc: FmuDescription) -> None:
    if desc.units:
        units = ET.SubElement(root, "UnitDefinitions")
        for unit in desc.units:
            ET.SubElement(units, "Unit", name=unit)
    categories = ET.SubElement(root, "LogCategories")
    for name, text in LOG_CATEGORIES:
        ET.SubElement(categories, "Category", name=name, description=text)
    ET.SubElement(root, "DefaultExperiment", startTime="0.0", stepSize=num(desc.spec.Ts))


_FMI2_COMMON = dict(canBeInstantiatedOnlyOncePerProcess="false", canNotUseMemoryManagementFunctions="true",
                    canGetAndSetFMUstate="true", canSerializeFMUstate="true")


def _fmi2_interface(root: ET.Element, tag: str, desc: FmuDescription, source_files: list[str], **attrs) -> None:
    element = ET.SubElement(root, tag, modelIdentifier=desc.model_identifier, **attrs, **_FMI2_COMMON)
    files = ET.SubElement(element, "SourceFiles")
    for name in source_files:
        ET.SubElement(files, "File", name=name)


def render_fmi2(desc: FmuDescription, source_files: list[str]) -> str:
    """modelDescription.xml for FMI 2.0 Co-Simulation (and Model Exchange for a continuous-time model),
    listing ``source_files`` (relative to sources/)."""
    root = ET.Element("fmiModelDescription", _header_attrs(desc, "2.0"), numberOfEventIndicators="0")
    if desc.structure:
        _fmi2_interface(root, "ModelExchange", desc, source_files, completedIntegratorStepNotNeeded="true",
                        providesDirectionalDerivative="true")
    _fmi2_interface(root, "CoSimulation", desc, source_files, canHandleVariableCommunicationStepSize="true",
                    canInterpolateInputs="false", providesDirectionalDerivative="false")
    _units_and_experiment(root, desc)
    index = {v.value_reference: i + 1 for i, v in enumerate(desc.variables)}  # FMI 2 indices are 1-based
    variables = ET.SubElement(root, "ModelVariables")
    for v in desc.variables:
        sv = ET.SubElement(variables, "ScalarVariable", _attrs(
            name=v.name, valueReference=str(v.value_reference), description=v.description,
            causality=v.causality, variability=v.variability, initial=v.initial))
        derivative = None if v.derivative is None else str(index[v.derivative])
        ET.SubElement(sv, v.type, _attrs(**_value_attrs(v), derivative=derivative))
    structure = ET.SubElement(root, "ModelStructure")
    for kind, tag in (("output", "Outputs"), ("derivative", "Derivatives"), ("initial", "InitialUnknowns")):
        unknowns = desc.dependencies(kind)
        if unknowns or kind != "derivative":
            group = ET.SubElement(structure, tag)
            for v, knowns in unknowns:
                ET.SubElement(group, "Unknown", index=str(index[v.value_reference]),
                              dependencies=" ".join(str(index[k]) for k in knowns))
    return _to_text(root)


_FMI3_TYPES = {"Real": "Float64", "Integer": "Int32", "Boolean": "Boolean"}


def render_fmi3(desc: FmuDescription) -> str:
    """modelDescription.xml for FMI 3.0 Co-Simulation (and Model Exchange for a continuous-time model; the
    sources are in sources/buildDescription.xml)."""
    root = ET.Element("fmiModelDescription", _header_attrs(desc, "3.0"))
    if desc.structure:
        ET.SubElement(root, "ModelExchange", modelIdentifier=desc.model_identifier, canGetAndSetFMUState="true",
                      canSerializeFMUState="true", providesDirectionalDerivatives="true",
                      providesAdjointDerivatives="false", needsCompletedIntegratorStep="false")
    ET.SubElement(root, "CoSimulation", modelIdentifier=desc.model_identifier,
                  canHandleVariableCommunicationStepSize="true", fixedInternalStepSize=num(desc.spec.Ts),
                  canGetAndSetFMUState="true", canSerializeFMUState="true",
                  providesDirectionalDerivatives="false", providesAdjointDerivatives="false",
                  hasEventMode="false", canReturnEarlyAfterIntermediateUpdate="false")
    _units_and_experiment(root, desc)
    variables = ET.SubElement(root, "ModelVariables")
    for v in desc.variables:
        derivative = None if v.derivative is None else str(v.derivative)
        element = ET.SubElement(variables, _FMI3_TYPES[v.type], _attrs(
            name=v.name, valueReference=str(v.value_reference), description=v.description,
            causality=v.causality, variability=v.variability, initial=v.initial, **_value_attrs(v),
            derivative=derivative))
        if v.size > 1 or v.role == "past":
            ET.SubElement(element, "Dimension", start=str(v.size))
    structure = ET.SubElement(root, "ModelStructure")
    for kind, tag in (("output", "Output"), ("derivative", "ContinuousStateDerivative"),
                      ("initial", "InitialUnknown")):
        for v, knowns in desc.dependencies(kind):
            ET.SubElement(structure, tag, valueReference=str(v.value_reference),
                          dependencies=" ".join(map(str, knowns)))
    return _to_text(root)


def render_build_description(desc: FmuDescription, source_files: list[str]) -> str:
    """FMI 3's sources/buildDescription.xml: one C99 source file set; no library to link (docs/fmu.md)."""
    root = ET.Element("fmiBuildDescription", fmiVersion="3.0")
    config = ET.SubElement(root, "BuildConfiguration", modelIdentifier=desc.model_identifier)
    files = ET.SubElement(config, "SourceFileSet", language="C99")
    for name in source_files:
        ET.SubElement(files, "SourceFile", name=name)
    return _to_text(root)
