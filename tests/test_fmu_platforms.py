"""One FMU with binaries for five platforms, cross-compiled here with Zig, and run for real.

``python -m nnfmu.export m.pt --platforms linux64,win64,darwin64,aarch64-linux,aarch64-darwin`` (FMI 2) and
``--platforms all`` (FMI 3) put every binary next to the sources; fmpy validates both. Then:

- the Windows DLL runs under Wine with an x86-64 Windows build of the test importer, and the aarch64 Linux
  library under QEMU user mode with an aarch64 build of it; both give the Linux binary's outputs;
- the macOS binaries are Mach-O dylibs of the right architecture that export the FMI functions (and
  nothing of nnfmu's own), the arm64 one code-signed as Apple silicon requires.

The sources' strict-C check and the CMake rebuild are in tests/test_fmu_model_exchange.py (the Model
Exchange FMUs list every template).
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import fmpy
import numpy as np
import pytest
import torch
from cross_tools import (Wine, binary_format, build_driver, macho_exports, outputs, qemu_or_skip, wine_or_skip,
                         zig_or_skip)
from fmpy.validation import validate_fmu
from fmu_cases import unzipped

from nnfmu.cli import main as nnfmu_main
from nnfmu.export.__main__ import main as export_main
from nnfmu.cbuild import run_compiler
from nnfmu.export.fmu import fmi_header_dir
from nnfmu.export.platforms import PLATFORMS, host_platform, parse_platforms, portable_flags
from nnfmu.models import ModelConfig, build_model, save_checkpoint

FMI2_NAMES = "linux64,win64,darwin64,aarch64-linux,aarch64-darwin"
#: The FMUs built: FMI version, --platforms and further options. All use the default "fast" profile (FMA, weight
#: panels, vectorised exp/tanh, x86 clones where the target's toolchain dispatches at load time).
CASES = {"fmi2": (2, FMI2_NAMES, ()), "fmi3": (3, "all", ()),
         "fmi2-float32": (2, "linux64,win64,aarch64-linux", ("--precision", "float32"))}
#: Agreement of each platform's binary with the Linux one: float64 differs by FMA contraction (x86 clones and
#: aarch64 fuse, the portable x86 baseline cannot) and Windows' libm; float32 by the same, at float32's eps.
RTOL = {"fmi2": 1e-12, "fmi3": 1e-12, "fmi2-float32": 1e-5}
FMI_FUNCTIONS = {2: ("fmi2Instantiate", "fmi2DoStep", "fmi2GetReal", "fmi2SetReal", "fmi2FreeInstance",
                     "fmi2GetFMUstate", "fmi2SerializeFMUstate"),
                 3: ("fmi3InstantiateCoSimulation", "fmi3DoStep", "fmi3GetFloat64", "fmi3SetFloat64",
                     "fmi3FreeInstance", "fmi3GetFMUState", "fmi3SerializeFMUState")}
N_STEPS = 150


@pytest.fixture(scope="module")
def fmus(tmp_path_factory):
    """A small GRU with an init window (its encoder and window code on every platform), exported for every
    platform as each of CASES: {case: fmu}."""
    zig_or_skip()
    folder = tmp_path_factory.mktemp("platforms")
    meta = {"name": "valve_gru", "Ts": 4e-5, "input_range": [[0.0, 10.0], [0.0, 10.0]],
            "inputs": [{"name": "u1", "unit": "V"}, {"name": "u2", "unit": "V"}],
            "outputs": [{"name": "s", "unit": "m"}, {"name": "p", "unit": "Pa"}]}
    torch.manual_seed(3)
    net = build_model(ModelConfig(arch="gru", n_u=2, n_y=2, hidden=8, init_window=3), meta)
    with torch.no_grad():
        net.u_mean.fill_(1.2), net.u_std.fill_(0.7)
        net.y_mean.copy_(torch.tensor([5e-4, 3e5])), net.y_std.copy_(torch.tensor([2e-4, 1e5]))
    checkpoint = save_checkpoint(folder / "m.pt", net)
    built = {}
    for case, (version, names, options) in CASES.items():
        built[case] = folder / f"{case}.fmu"
        argv = [str(checkpoint), "-o", str(built[case]), "--name", "valve_gru", "--fmi-version", str(version),
                "--platforms", names]
        assert export_main([*argv, *options]) == 0
    return built


@pytest.fixture(scope="module")
def drivers(tmp_path_factory):
    """The test importer for this machine, and a function that builds it once for another platform."""
    folder = tmp_path_factory.mktemp("drivers")
    host = folder / "fmu_driver"
    run_compiler(["-std=c99", "-O2", f"-I{fmi_header_dir()}", str(Path(__file__).parent / "c" / "fmu_driver.c"),
                  "-o", str(host), "-ldl"], what="compiling the test importer")
    built: dict[str, Path] = {}

    def for_platform(name: str) -> Path:
        if name not in built:
            built[name] = build_driver(PLATFORMS[name], folder)
        return built[name]

    return for_platform, host


@pytest.fixture(scope="module")
def wine(tmp_path_factory):
    wine_or_skip()
    session = Wine(tmp_path_factory.mktemp("wine-prefix"))
    yield session
    session.close()


def binary(fmus: dict, case: str, platform: str) -> Path:
    target = PLATFORMS[platform]
    return unzipped(fmus[case]) / "binaries" / target.folder(CASES[case][0]) / f"valve_gru{target.suffix}"


def driver_args(fmus: dict, case: str) -> list[str]:
    version = CASES[case][0]
    md = fmpy.read_model_description(str(unzipped(fmus[case])))
    return [md.guid if version == 2 else md.instantiationToken, str(version), repr(4e-5), "run", str(N_STEPS)]


def assert_same_outputs(got: np.ndarray, want: np.ndarray, case: str) -> None:
    """float64: relative 1e-12 per value. float32: 1e-5 of each output's size, since a value that passes near zero
    (the outputs start at their training means) keeps float32's absolute rounding, not its relative one."""
    if case != "fmi2-float32":
        np.testing.assert_allclose(got, want, rtol=RTOL[case], atol=0)
        return
    scale = np.abs(want).max(axis=0)
    np.testing.assert_allclose(got / scale, want / scale, rtol=RTOL[case], atol=RTOL[case])


def linux_outputs(fmus: dict, case: str, driver: Path) -> np.ndarray:
    done = subprocess.run([str(driver), str(binary(fmus, case, "x86_64-linux")), *driver_args(fmus, case)],
                          capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stdout + done.stderr
    return np.array(outputs(done.stdout.splitlines()))


@pytest.mark.parametrize("version", [2, 3])
def test_one_fmu_holds_every_platform_and_validates(fmus, version):
    case = f"fmi{version}"
    fmu = fmus[case]
    assert validate_fmu(str(fmu)) == []
    assert "nnfmu_gemv_panel(" in (unzipped(fmu) / "sources" / "model_casadi.c").read_text()  # the fast profile
    assert set(fmpy.supported_platforms(str(fmu))) == {"c-code", "linux64", "win64", "darwin64"}
    expected = {"x86_64-linux": ("ELF shared object", "x86_64"), "aarch64-linux": ("ELF shared object", "aarch64"),
                "x86_64-windows": ("PE DLL", "x86_64"), "x86_64-darwin": ("Mach-O dylib", "x86_64"),
                "aarch64-darwin": ("Mach-O dylib", "aarch64")}
    assert {p: binary_format(binary(fmus, case, p)) for p in expected} == expected
    folders = sorted(p.name for p in (unzipped(fmu) / "binaries").iterdir())
    assert folders == sorted(PLATFORMS[p].folder(version) for p in expected)


@pytest.mark.parametrize("case", CASES)
def test_windows_dll_under_wine_gives_the_linux_outputs(fmus, drivers, wine, case):
    for_platform, host = drivers
    exe = for_platform("x86_64-windows")
    done = wine.run(exe, Wine.path(binary(fmus, case, "x86_64-windows")), *driver_args(fmus, case))
    assert done.returncode == 0, done.stdout[-2000:] + done.stderr[-2000:]
    got, want = np.array(outputs(done.stdout.splitlines())), linux_outputs(fmus, case, host)
    assert got.shape == want.shape == (N_STEPS, 2) and np.ptp(want, axis=0).min() > 0
    assert_same_outputs(got, want, case)


@pytest.mark.parametrize("case", CASES)
def test_aarch64_library_under_qemu_gives_the_linux_outputs(fmus, drivers, case):
    qemu = qemu_or_skip()
    for_platform, host = drivers
    exe = for_platform("aarch64-linux")
    done = subprocess.run([*qemu, str(exe), str(binary(fmus, case, "aarch64-linux")), *driver_args(fmus, case)],
                          capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stdout[-2000:] + done.stderr[-2000:]
    lines = done.stdout.splitlines()
    assert lines[0] == "libm loaded before the FMU: no"  # the aarch64 library links its own libm
    got, want = np.array(outputs(lines)), linux_outputs(fmus, case, host)
    assert got.shape == want.shape == (N_STEPS, 2)
    assert_same_outputs(got, want, case)


@pytest.mark.parametrize("platform", ["x86_64-darwin", "aarch64-darwin"])
@pytest.mark.parametrize("version", [2, 3])
def test_macos_dylibs_export_the_fmi_functions(fmus, version, platform):
    exported, signed = macho_exports(binary(fmus, f"fmi{version}", platform))
    assert set(FMI_FUNCTIONS[version]) <= exported
    assert not [name for name in exported if name.startswith(("nnfmu_", "casadi_"))]  # the model's code stays inside
    assert signed or platform == "x86_64-darwin"  # arm64 code must carry (at least an ad-hoc) signature


def test_platform_names_flags_and_a_missing_toolchain(monkeypatch, tmp_path, capsys):
    assert [p.fmi3 for p in parse_platforms("linux64, x86_64-windows,win64")] == ["x86_64-linux", "x86_64-windows"]
    assert len(parse_platforms("all")) == 5 and parse_platforms(None) == (host_platform(),)
    assert portable_flags(["-O3", "-march=native", "-mavx2", "-mfma", "-std=c99"]) == ["-O3", "-std=c99"]
    assert nnfmu_main(["physics-fmu", "valve", "-o", str(tmp_path / "v.fmu"), "--platforms", "linux64,sparc"]) == 2
    assert "unknown platform 'sparc'; choose from host, all, aarch64-darwin" in capsys.readouterr().err
    monkeypatch.setitem(sys.modules, "ziglang", None)  # as if the extra 'cross' were not installed
    assert nnfmu_main(["physics-fmu", "valve", "-o", str(tmp_path / "v.fmu"), "--platforms", "win64"]) == 2
    assert "needs the Zig toolchain: pip install 'nnfmu[cross]'" in capsys.readouterr().err
    assert list(tmp_path.iterdir()) == []
