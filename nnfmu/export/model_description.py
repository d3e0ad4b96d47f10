"""One description of an FMU's variables, rendered into modelDescription.xml (FMI 2 and 3) and a C header.

Value references are assigned once, in :func:`describe`, and every artefact
that names a variable (the XML for FMI 2.0 or 3.0, FMI 3's
``buildDescription.xml`` and the wrapper's ``nnfmu_model.h``) is rendered
from that one :class:`FmuDescription`. The layout is::

    vr 0                     time         independent
    vr 1                     Ts           local constant, the sample time in s
    vr 2 ...                 inputs       input, continuous (held over each sample)
    then                     outputs      output, discrete (they change at sample times only)
    then                     <y>_start    parameter, fixed: the initial outputs y0
    then                     parameters   parameter, tunable: the ``p`` port

The outputs at t0 are the ``<y>_start`` values, so they are initial unknowns
that depend on those parameters only; outputs never depend directly on inputs
(no feedthrough).
"""

from __future__ import annotations

import math
import re
import xml.etree.ElementTree as ET
from dataclasses import dataclass

from nnfmu import __version__
from nnfmu.errors import FmuBuildError
from nnfmu.system import SystemSpec

GENERATION_TOOL = f"nnfmu {__version__}"
LOG_CATEGORIES = (("logStatusError", "errors: bad calls, step sizes, non-finite values"),
                  ("logStatusWarning", "warnings"))
_C_IDENTIFIER = re.compile(r"[A-Za-z_][A-Za-z0-9_]*")


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


@dataclass(frozen=True)
class FmuDescription:
    """Everything that names a variable or identifies the FMU; rendered by the functions of this module."""

    spec: SystemSpec
    variables: tuple[ScalarVariable, ...]
    model_identifier: str
    token: str
    generation_time: str

    def by_role(self, role: str) -> tuple[ScalarVariable, ...]:
        return tuple(v for v in self.variables if v.role == role)

    @property
    def units(self) -> list[str]:
        return sorted({v.unit for v in self.variables if v.unit})


def check_spec(spec: SystemSpec) -> None:
    """Raise FmuBuildError if ``spec`` cannot become an FMU (C identifier, finite starts)."""
    if not _C_IDENTIFIER.fullmatch(spec.name):
        raise FmuBuildError(
            f"the model name {spec.name!r} becomes the FMU's modelIdentifier and must be an ASCII C "
            f"identifier; rename it (letters a-z, A-Z, digits, '_')")
    for v in spec.inputs + spec.outputs + spec.parameters:
        if not math.isfinite(v.start):
            raise FmuBuildError(f"the start value of {v.name!r} is {v.start!r}; give it a finite start value")


def describe(spec: SystemSpec, token: str, generation_time: str) -> FmuDescription:
    """Assign value references (see the module docstring) and return the one description of the FMU."""
    check_spec(spec)
    rows = [
        ("time", "independent", "continuous", None, None, "s", "simulation time", "time", 0),
        ("Ts", "local", "constant", "exact", spec.Ts, "s", "sample time of the discrete-time model", "Ts", 0),
    ]
    rows += [(v.name, "input", "continuous", None, v.start, v.unit, v.description, "input", i)
             for i, v in enumerate(spec.inputs)]
    rows += [(v.name, "output", "discrete", "calculated", None, v.unit, v.description, "output", i)
             for i, v in enumerate(spec.outputs)]
    rows += [(f"{v.name}_start", "parameter", "fixed", "exact", v.start, v.unit,
              f"initial value y0 of output {v.name} (the output at the start time)", "output_start", i)
             for i, v in enumerate(spec.outputs)]
    rows += [(v.name, "parameter", "tunable", "exact", v.start, v.unit, v.description, "parameter", i)
             for i, v in enumerate(spec.parameters)]
    variables = tuple(ScalarVariable(name, vr, *rest) for vr, (name, *rest) in enumerate(rows))
    return FmuDescription(spec, variables, spec.name, token, generation_time)


def _num(x: float) -> str:
    """Shortest round-trip decimal of a float, valid in XML and as a C double literal."""
    text = repr(float(x))
    return text if any(c in text for c in ".en") else text + ".0"


def _to_text(root: ET.Element) -> str:
    ET.indent(root, space="  ")
    return '<?xml version="1.0" encoding="UTF-8"?>\n' + ET.tostring(root, encoding="unicode") + "\n"


def _attrs(**kw) -> dict[str, str]:
    return {k: v for k, v in kw.items() if v not in (None, "")}


def _header_attrs(desc: FmuDescription, fmi_version: str) -> dict[str, str]:
    spec = desc.spec
    token_key = "guid" if fmi_version == "2.0" else "instantiationToken"
    return _attrs(fmiVersion=fmi_version, modelName=spec.name, **{token_key: desc.token},
                  description=spec.description or f"{spec.name}: discrete-time model, Ts = {spec.Ts:g} s",
                  generationTool=GENERATION_TOOL, generationDateAndTime=desc.generation_time,
                  variableNamingConvention="flat")


def _units_and_experiment(root: ET.Element, desc: FmuDescription) -> None:
    if desc.units:
        units = ET.SubElement(root, "UnitDefinitions")
        for unit in desc.units:
            ET.SubElement(units, "Unit", name=unit)
    categories = ET.SubElement(root, "LogCategories")
    for name, text in LOG_CATEGORIES:
        ET.SubElement(categories, "Category", name=name, description=text)
    ET.SubElement(root, "DefaultExperiment", startTime="0.0", stepSize=_num(desc.spec.Ts))


def render_fmi2(desc: FmuDescription, source_files: list[str]) -> str:
    """modelDescription.xml for FMI 2.0 Co-Simulation, listing ``source_files`` (relative to sources/)."""
    root = ET.Element("fmiModelDescription", _header_attrs(desc, "2.0"), numberOfEventIndicators="0")
    cs = ET.SubElement(root, "CoSimulation", modelIdentifier=desc.model_identifier,
                       canHandleVariableCommunicationStepSize="true", canInterpolateInputs="false",
                       canBeInstantiatedOnlyOncePerProcess="false", canNotUseMemoryManagementFunctions="true",
                       canGetAndSetFMUstate="true", canSerializeFMUstate="true",
                       providesDirectionalDerivative="false")
    files = ET.SubElement(cs, "SourceFiles")
    for name in source_files:
        ET.SubElement(files, "File", name=name)
    _units_and_experiment(root, desc)
    variables = ET.SubElement(root, "ModelVariables")
    for v in desc.variables:
        sv = ET.SubElement(variables, "ScalarVariable", _attrs(
            name=v.name, valueReference=str(v.value_reference), description=v.description,
            causality=v.causality, variability=v.variability, initial=v.initial))
        ET.SubElement(sv, "Real", _attrs(start=None if v.start is None else _num(v.start), unit=v.unit))
    index = {v.value_reference: i + 1 for i, v in enumerate(desc.variables)}  # FMI 2 indices are 1-based
    structure = ET.SubElement(root, "ModelStructure")
    outputs = ET.SubElement(structure, "Outputs")
    for v in desc.by_role("output"):
        ET.SubElement(outputs, "Unknown", index=str(index[v.value_reference]), dependencies="")
    initial = ET.SubElement(structure, "InitialUnknowns")
    for v, s in zip(desc.by_role("output"), desc.by_role("output_start"), strict=True):
        ET.SubElement(initial, "Unknown", index=str(index[v.value_reference]),
                      dependencies=str(index[s.value_reference]))
    return _to_text(root)


def render_fmi3(desc: FmuDescription) -> str:
    """modelDescription.xml for FMI 3.0 Co-Simulation (the sources are in sources/buildDescription.xml)."""
    root = ET.Element("fmiModelDescription", _header_attrs(desc, "3.0"))
    ET.SubElement(root, "CoSimulation", modelIdentifier=desc.model_identifier,
                  canHandleVariableCommunicationStepSize="true", fixedInternalStepSize=_num(desc.spec.Ts),
                  canGetAndSetFMUState="true", canSerializeFMUState="true",
                  providesDirectionalDerivatives="false", providesAdjointDerivatives="false",
                  hasEventMode="false", canReturnEarlyAfterIntermediateUpdate="false")
    _units_and_experiment(root, desc)
    variables = ET.SubElement(root, "ModelVariables")
    for v in desc.variables:
        ET.SubElement(variables, "Float64", _attrs(
            name=v.name, valueReference=str(v.value_reference), description=v.description,
            causality=v.causality, variability=v.variability, initial=v.initial,
            start=None if v.start is None else _num(v.start), unit=v.unit))
    structure = ET.SubElement(root, "ModelStructure")
    for v in desc.by_role("output"):
        ET.SubElement(structure, "Output", valueReference=str(v.value_reference), dependencies="")
    for v, s in zip(desc.by_role("output"), desc.by_role("output_start"), strict=True):
        ET.SubElement(structure, "InitialUnknown", valueReference=str(v.value_reference),
                      dependencies=str(s.value_reference))
    return _to_text(root)


def render_build_description(desc: FmuDescription, source_files: list[str]) -> str:
    """FMI 3's sources/buildDescription.xml: one C99 source file set, linked against libm."""
    root = ET.Element("fmiBuildDescription", fmiVersion="3.0")
    config = ET.SubElement(root, "BuildConfiguration", modelIdentifier=desc.model_identifier)
    files = ET.SubElement(config, "SourceFileSet", language="C99")
    for name in source_files:
        ET.SubElement(files, "SourceFile", name=name)
    ET.SubElement(config, "Library", name="m", external="true", description="the C math library (libm)")
    return _to_text(root)


def _c_string(text: str) -> str:
    """A C string literal of ``text`` (UTF-8; anything but plain ASCII escaped in octal)."""
    out = []
    for byte in text.encode("utf-8"):
        ch = chr(byte)
        out.append(ch if 32 <= byte < 127 and ch not in '\\"?%' else f"\\{byte:03o}")
    return '"' + "".join(out) + '"'


def _c_array(ctype: str, name: str, values: list[str]) -> str:
    body = ", ".join(values) if values else "0"  # C forbids empty arrays: a placeholder, never read
    return f"static const {ctype} {name}[{max(1, len(values))}] = {{{body}}};"


def render_c_header(desc: FmuDescription, n_x: int, entry_points: dict[str, str]) -> str:
    """``nnfmu_model.h``: sizes, value-reference layout, start values and the prefixed CasADi entry points."""
    spec = desc.spec
    first = {role: desc.by_role(role)[0].value_reference if desc.by_role(role) else len(desc.variables)
             for role in ("input", "output", "output_start", "parameter")}
    lines = [
        "/* Generated by nnfmu from the description that also produced modelDescription.xml. Do not edit. */",
        "#ifndef NNFMU_MODEL_H", "#define NNFMU_MODEL_H", "",
        f"#define NNFMU_MODEL_IDENTIFIER {_c_string(desc.model_identifier)}",
        f"#define NNFMU_TOKEN {_c_string(desc.token)}",
        f"#define NNFMU_TS {_num(spec.Ts)} /* sample time, s */",
        f"#define NNFMU_NU {spec.n_u}", f"#define NNFMU_NY {spec.n_y}", f"#define NNFMU_NP {spec.n_p}",
        f"#define NNFMU_NX {n_x}", "",
        "/* value references: u[i] has NNFMU_VR_U + i, and so on */",
        "#define NNFMU_VR_TIME 0", "#define NNFMU_VR_TS 1",
        f"#define NNFMU_VR_U {first['input']}", f"#define NNFMU_VR_Y {first['output']}",
        f"#define NNFMU_VR_Y_START {first['output_start']}", f"#define NNFMU_VR_P {first['parameter']}",
        f"#define NNFMU_N_VR {len(desc.variables)}", "",
        "/* the CasADi functions, with this model's unique symbol prefix */",
    ]
    lines += [f"#define {macro} {symbol}" for macro, symbol in sorted(entry_points.items())]
    lines.append("")
    for role, c_name in (("input", "u"), ("output", "y"), ("parameter", "p")):
        names = [_c_string(v.name) for v in desc.by_role(role)]
        lines.append(_c_array("char* const", f"nnfmu_{c_name}_names", names))
    starts = {"u": spec.inputs, "y": spec.outputs, "p": spec.parameters}
    for c_name, group in starts.items():
        lines.append(_c_array("double", f"nnfmu_{c_name}_start", [_num(v.start) for v in group]))
    lines += ["", "#endif /* NNFMU_MODEL_H */", ""]
    return "\n".join(lines)
