"""FMUs driven from C (tests/c/fmu_driver.c: dlopen, no Python per step, built without libm).

- a run past t = 256 s and past 10^7 samples at Ts = 40 us, at fmpy's communication points, equals
  stepping in blocks of 1000 samples bit for bit, and a step of 1e9 s is refused at once;
- binaries rebuilt from the shipped sources, by fmpy's CMake route and by a plain ``cc -shared``,
  load in that importer without libm and compute what CasadiModel.simulate computes.
"""

from __future__ import annotations

import os
import re
import shutil
import subprocess
from pathlib import Path

import fmpy
import numpy as np
import pytest
from fmpy.build import build_platform_binary
from fmu_cases import MODELS, built_fmu, get_model, unzipped

from nnfmu.cbuild import run_compiler
from nnfmu.export.fmu import fmi_header_dir, platform_folder

DRIVER = Path(__file__).parent / "c" / "fmu_driver.c"


@pytest.fixture(scope="module")
def driver(tmp_path_factory) -> Path:
    exe = tmp_path_factory.mktemp("driver") / "fmu_driver"
    run_compiler(["-std=c99", "-O2", f"-I{fmi_header_dir()}", str(DRIVER), "-o", str(exe), "-ldl"],
                 what="compiling the test importer")  # no -lm: the FMU must bring its maths itself
    return exe


def drive(driver: Path, binary: Path, fmu_dir: Path, version: int, Ts: float, *args) -> list[str]:
    md = fmpy.read_model_description(str(fmu_dir))
    token = md.guid if version == 2 else md.instantiationToken
    done = subprocess.run([str(driver), str(binary), token, str(version), repr(Ts), *map(str, args)],
                          capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stdout[-3000:] + done.stderr
    lines = done.stdout.splitlines()
    assert lines[0] == "libm loaded before the FMU: no"
    return lines


def driver_inputs(n: int) -> np.ndarray:
    """The driver's inputs for samples 0 .. n-1 (exact rationals, computed as in C)."""
    k = np.arange(n)
    return np.column_stack([((k * 7) % 13) / 13.0 * 2.0 + 0.5, ((k * 5) % 11) / 11.0 * 2.0])


@pytest.mark.parametrize("version, samples, start", [(2, 10_500_000, 0.0), (3, 200_000, 255.0)])
def test_long_run_at_fmpy_communication_points_from_c(driver, version, samples, start):
    fmu_dir = unzipped(built_fmu("valve_gru", version))
    binary = next((fmu_dir / "binaries").rglob("*.so"))
    lines = drive(driver, binary, fmu_dir, version, 4e-5, "schedule", samples, 1000, start)
    summary = next(line for line in lines if line.startswith("samples"))
    fields = dict(zip(summary.split()[0::2], summary.split()[1::2]))
    assert fields["worst"] == "0" and fields["mismatches"] == "0", lines[-5:]  # every step OK; bit-equal
    assert float(fields["time"]) == pytest.approx(start + samples * 4e-5, rel=1e-15)
    assert lines[-1] == "huge step status 3"
    assert "would take 25000000000000 samples" in lines[-2]
    if samples <= 200_000:  # short enough to check against the reference free run
        u = np.repeat(driver_inputs(samples // 1000 + 1), 1000, axis=0)[:samples + 1]
        want = get_model("valve_gru").simulate(u, [v.start for v in get_model("valve_gru").spec.outputs])[-1]
        y = np.array(summary.split()[-2:], dtype=float)
        np.testing.assert_allclose(y, want, rtol=1e-10)


def _rebuild_with_cc(folder: Path, version: int) -> None:
    md = fmpy.read_model_description(str(folder))
    sources = [str(folder / "sources" / f) for f in md.buildConfigurations[0].sourceFileSets[0].sourceFiles]
    out = folder / "binaries" / platform_folder(version) / f"{md.coSimulation.modelIdentifier}.so"
    out.parent.mkdir(parents=True)
    run_compiler(["-shared", "-fPIC", "-O2", f"-I{folder / 'sources'}", *sources, "-o", str(out)],
                 what="a plain source build (no -lm)")


@pytest.mark.parametrize("version", [2, 3])
@pytest.mark.parametrize("route", ["fmpy-cmake", "cc"])
def test_binary_rebuilt_from_sources_loads_without_libm(driver, tmp_path, version, route):
    model = MODELS["nonlinear"]  # tanh in every step
    folder = tmp_path / "unzipped"
    shutil.copytree(unzipped(built_fmu("nonlinear", version)), folder)
    shutil.rmtree(folder / "binaries")
    if route == "cc":
        _rebuild_with_cc(folder, version)
    else:
        (tmp_path / "build").mkdir()
        build_platform_binary(os.path.abspath(folder), build_dir=os.path.abspath(tmp_path / "build"))
    (binary,) = (folder / "binaries").rglob("tinynet.so")
    if shutil.which("nm"):  # binutils, beside the compiler; the load below is the real check
        undefined = subprocess.run(["nm", "-D", "--undefined-only", str(binary)], capture_output=True,
                                   text=True).stdout
        assert not re.search(r"\b(tanh|exp|sin|cos|sincos|fmax|fmin|floor)\b", undefined), undefined
    lines = drive(driver, binary, folder, version, model.spec.Ts, "run", 150)
    got = np.array([line.split()[1:] for line in lines if line.startswith("y ")], dtype=float)
    want = model.simulate(driver_inputs(151), [v.start for v in model.spec.outputs])[1:]
    np.testing.assert_allclose(got, want, rtol=1e-12, atol=1e-15)
