"""build_fmu: what the .fmu contains (model description, sources, binary) and how a build fails."""

from __future__ import annotations

import dataclasses
import re
import zipfile

import casadi as ca
import fmpy
import numpy as np
import pytest
from fmpy.validation import validate_fmu
from fmu_cases import MODELS, built_fmu, exported_symbols

from nnfmu.errors import ConfigError, FmuBuildError, ShapeError
from nnfmu.export import build_fmu, codegen
from nnfmu.export.fmu import BuildOptions
from nnfmu.system import CasadiModel, SystemSpec, Variable

CASES = [("linear", 2), ("linear", 3), ("nonlinear", 2), ("nonlinear", 3)]


@pytest.mark.parametrize("name, version", CASES)
def test_fmu_passes_fmpy_validation(name, version):
    assert validate_fmu(str(built_fmu(name, version))) == []


@pytest.mark.parametrize("name, version", CASES)
def test_variables_carry_names_units_starts_and_sample_time(name, version):
    model = MODELS[name]
    spec = model.spec
    md = fmpy.read_model_description(str(built_fmu(name, version)))
    by_name = {v.name: v for v in md.modelVariables}
    assert md.coSimulation.modelIdentifier == spec.name
    assert float(md.defaultExperiment.stepSize) == spec.Ts
    assert float(by_name["Ts"].start) == spec.Ts and by_name["Ts"].variability == "constant"
    for v in spec.inputs:
        assert (by_name[v.name].causality, by_name[v.name].unit) == ("input", v.unit or None)
    for v in spec.outputs:
        out, start = by_name[v.name], by_name[f"{v.name}_start"]
        assert (out.causality, out.unit, out.description) == ("output", v.unit or None, v.description or None)
        assert (start.causality, start.variability, float(start.start)) == ("parameter", "fixed", v.start)
    for v in spec.parameters:
        assert (by_name[v.name].causality, by_name[v.name].variability) == ("parameter", "tunable")
        assert float(by_name[v.name].start) == v.start
    outputs = {u.variable.name for u in md.outputs}
    assert outputs == {v.name for v in spec.outputs}
    assert all(u.dependencies == [] for u in md.outputs), "outputs must not depend on inputs (no feedthrough)"


@pytest.mark.parametrize("name, version", CASES)
def test_c_header_and_xml_share_value_references(name, version):
    """nnfmu_model.h and modelDescription.xml come from one description: their VRs agree."""
    fmu = built_fmu(name, version)
    with zipfile.ZipFile(fmu) as zf:
        header = zf.read("sources/nnfmu_model.h").decode()
    macros = {k: int(v) for k, v in re.findall(r"#define NNFMU_(VR_\w+|N\w?) (\d+)\b", header)}
    md = fmpy.read_model_description(str(fmu))
    vr = {v.name: v.valueReference for v in md.modelVariables}
    spec = MODELS[name].spec
    assert vr["time"] == macros["VR_TIME"] and vr["Ts"] == macros["VR_TS"]
    for group, first in ((spec.inputs, "VR_U"), (spec.outputs, "VR_Y"), (spec.parameters, "VR_P")):
        assert [vr[v.name] for v in group] == [macros[first] + i for i in range(len(group))]
    assert [vr[f"{v.name}_start"] for v in spec.outputs] == [macros["VR_Y_START"] + i for i in range(spec.n_y)]
    assert (macros["NU"], macros["NY"], macros["NP"], macros["NX"]) == (spec.n_u, spec.n_y, spec.n_p, MODELS[name].n_x)


@pytest.mark.parametrize("version, platform_dir", [(2, "binaries/linux64/"), (3, "binaries/x86_64-linux/")])
def test_fmu_ships_sources_headers_and_platform_binary(version, platform_dir):
    fmu = built_fmu("nonlinear", version)
    names = set(zipfile.ZipFile(fmu).namelist())
    assert f"{platform_dir}tinynet.so" in names
    core = ["nnfmu_model.c", "nnfmu_me_model.c", "nnfmu_log.c", "nnfmu_core.c", "nnfmu_variables.c", "nnfmu_step.c",
            "nnfmu_state.c", "nnfmu_me.c", "nnfmu_libm.c"]
    sources = {"model_casadi.c", "model_me_casadi.c", *core, f"nnfmu_fmi{version}.c", f"fmi{version}Functions.h",
               "nnfmu_model.h", "nnfmu_core.h", "nnfmu_instance.h", "nnfmu_libm.h"}
    assert {f"sources/{s}" for s in sources} <= names
    md = fmpy.read_model_description(str(fmu))
    listed = md.buildConfigurations[0].sourceFileSets[0].sourceFiles
    # one wrapper per FMI version holds every entry point, Model Exchange ones included, in every FMU
    wrapper = ["nnfmu_fmi2.c", "nnfmu_fmi2_me.c"] if version == 2 else \
        ["nnfmu_fmi3.c", "nnfmu_fmi3_me.c", "nnfmu_fmi3_unsupported.c"]
    assert sorted(listed) == sorted([*core, *wrapper])  # model_casadi.c is compiled through nnfmu_model.c
    if version == 3:
        assert "sources/buildDescription.xml" in names


def test_generated_code_is_patched_and_keeps_no_mutable_state():
    with zipfile.ZipFile(built_fmu("nonlinear", 2)) as zf:
        source = zf.read("sources/model_casadi.c").decode()
    assert "casadi_real* NNFMU_RESTRICT zi = z + i*nrow_x;" in source, "the vectorisable kernel is missing"
    assert "NNFMU_CLONES\nstatic int casadi_f" in source
    assert "#pragma GCC visibility push(hidden)" in source
    assert not re.search(r"^\s*static\s+(?!const\b)[^(\n]*[;=]", source, re.M)


def test_only_fmi_functions_are_exported_and_symbols_are_unique_per_model():
    fmu_a, fmu_b = built_fmu("linear", 2), built_fmu("nonlinear", 2)
    prefix_a, prefix_b = (codegen.symbol_prefix(MODELS[n]) for n in ("linear", "nonlinear"))
    assert prefix_a != prefix_b
    seen = exported_symbols(fmu_a, ["fmi2DoStep", f"{prefix_a}_entry_step", f"{prefix_a}_copy"])
    assert seen == {"fmi2DoStep": True, f"{prefix_a}_entry_step": False, f"{prefix_a}_copy": False}
    assert exported_symbols(fmu_b, ["fmi2Instantiate", f"{prefix_b}_entry_init"]) == {
        "fmi2Instantiate": True, f"{prefix_b}_entry_init": False}


def test_fmi3_binary_exports_the_whole_fmi3_api():
    names = ["fmi3GetVersion", "fmi3InstantiateCoSimulation", "fmi3InstantiateModelExchange", "fmi3DoStep",
             "fmi3GetFloat64", "fmi3GetClock", "fmi3UpdateDiscreteStates", "fmi3GetNumberOfContinuousStates",
             "fmi3SerializeFMUState", "fmi3ActivateModelPartition", "fmi3GetVariableDependencies"]
    assert all(exported_symbols(built_fmu("linear", 3), names).values())


def test_compile_error_raises_with_compiler_stderr_and_leaves_nothing(tmp_path, monkeypatch):
    original = codegen.patch_source
    monkeypatch.setattr(codegen, "patch_source",
                        lambda src, **kw: original(src, **kw) + "\nthis_is_not_c nnfmu_marker;\n")
    out = tmp_path / "broken.fmu"
    with pytest.raises(FmuBuildError, match=r"compiling the FMU binary of 'oscillator' for \S+ failed: "
                                            r".* exited with status \d+: .*error.*this_is_not_c") as info:
        build_fmu(MODELS["linear"], out)
    assert "\n" not in str(info.value), "one line; the compiler's whole output is .stderr"
    assert "this_is_not_c" in info.value.stderr
    assert list(tmp_path.iterdir()) == [], "a failed build must leave no file behind"


def test_failed_build_keeps_an_existing_fmu(tmp_path):
    out = tmp_path / "model.fmu"
    out.write_bytes(b"previous build")
    with pytest.raises(FmuBuildError, match="unrecognized|unknown|error"):
        build_fmu(MODELS["linear"], out, options=BuildOptions(flags=("-O2", "--no-such-flag-for-nnfmu")))
    assert out.read_bytes() == b"previous build"
    assert [p.name for p in tmp_path.iterdir()] == ["model.fmu"]


def test_missing_compiler_is_a_clear_error(tmp_path, monkeypatch):
    monkeypatch.delenv("CC", raising=False)
    monkeypatch.setenv("PATH", str(tmp_path))  # no cc, gcc or clang here
    with pytest.raises(FmuBuildError, match=r"no C compiler found: looked for 'cc', 'gcc', 'clang'.*install one"):
        build_fmu(MODELS["linear"], tmp_path / "m.fmu")
    with pytest.raises(FmuBuildError, match=r"no C compiler found: looked for '/nowhere/cc'"):
        build_fmu(MODELS["linear"], tmp_path / "m.fmu", options=BuildOptions(compiler="/nowhere/cc"))
    assert not (tmp_path / "m.fmu").exists()


@pytest.mark.parametrize("kwargs, error, match", [
    ({"fmi_version": 1}, ConfigError, "fmi_version must be 2 or 3, got 1"),
    ({"fmi_version": "3"}, ConfigError, "fmi_version must be 2 or 3"),
])
def test_bad_fmi_version(tmp_path, kwargs, error, match):
    with pytest.raises(error, match=match):
        build_fmu(MODELS["linear"], tmp_path / "m.fmu", **kwargs)


def test_bad_arguments_name_the_fix(tmp_path):
    with pytest.raises(TypeError, match="expects an nnfmu.system.CasadiModel, got tuple"):
        build_fmu((MODELS["linear"].init, MODELS["linear"].step), tmp_path / "m.fmu")
    with pytest.raises(ConfigError, match=r"must end in .fmu, got .*model.zip"):
        build_fmu(MODELS["linear"], tmp_path / "model.zip")
    with pytest.raises(FmuBuildError, match="does not exist; create it first"):
        build_fmu(MODELS["linear"], tmp_path / "missing" / "m.fmu")


def test_model_name_must_be_an_ascii_c_identifier(tmp_path):
    m = MODELS["linear"]  # refused where the spec is made (nnfmu.identifiers), before any build
    with pytest.raises(ShapeError, match=r"model name 'Ventilmodell_ö' is not a C identifier; use ASCII letters"):
        SystemSpec("Ventilmodell_ö", m.spec.Ts, m.spec.inputs, m.spec.outputs)


def test_non_finite_start_value_is_rejected(tmp_path):
    m = MODELS["linear"]
    spec = SystemSpec("osc", m.spec.Ts, m.spec.inputs, [Variable("pos", start=np.nan), Variable("vel")])
    with pytest.raises(FmuBuildError, match="start value of 'pos' is nan; give it a finite start value"):
        build_fmu(CasadiModel(m.init, m.step, spec), tmp_path / "m.fmu")


@pytest.mark.parametrize("name", ["my__model_", "_valve", "x"])
def test_symbol_prefix_is_valid_for_casadi_and_c(name):
    m = MODELS["linear"]
    prefix = codegen.symbol_prefix(CasadiModel(m.init, m.step, dataclasses.replace(m.spec, name=name)))
    assert re.fullmatch(r"nnfmu_[A-Za-z0-9_]+", prefix)
    assert ca.Function.check_name(f"{prefix}_entry_init") and ca.Function.check_name(prefix)
