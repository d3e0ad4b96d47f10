"""Running and inspecting cross-compiled FMU binaries here (tests/test_fmu_platforms.py and the Model Exchange tests).

- the test importer tests/c/fmu_driver.c built for a target with ``zig cc``;
- Wine (Debian's ``wine``) for Windows, QEMU user mode (``qemu-user``) with Debian's aarch64 C library
  (``libc6-arm64-cross``) for ARM64 Linux: ``make setup`` installs them where it can; a test that cannot
  run one skips that part and names the package;
- binary headers (ELF, PE, Mach-O) and a Mach-O symbol table reader for the macOS binaries;
- the strict-C check of the shipped sources (C99 without GNU extensions or VLAs, as MSVC needs).
"""

from __future__ import annotations

import os
import shutil
import struct
import subprocess
from pathlib import Path

import pytest

from nnfmu.cbuild import run_compiler
from nnfmu.export.fmu import fmi_header_dir
from nnfmu.export.platforms import PLATFORMS, Platform

DRIVER = Path(__file__).parent / "c" / "fmu_driver.c"
AARCH64_SYSROOT = Path("/usr/aarch64-linux-gnu")


def zig_or_skip() -> Path:
    from nnfmu.export.platforms import zig_executable

    try:
        return zig_executable()
    except Exception as exc:  # ConfigError: ziglang missing
        pytest.skip(f"the ziglang package is not installed (pip install 'nnfmu[cross]'): {exc}")


def build_driver(target: Platform, folder: Path) -> Path:
    """tests/c/fmu_driver.c as an executable of ``target`` (no -lm, so the FMU must bring its maths)."""
    exe = folder / f"fmu_driver-{target.fmi3}{'.exe' if target.suffix == '.dll' else ''}"
    libs = ["-ldl"] if target.suffix == ".so" else []
    run_compiler(["cc", "-target", target.zig_target, "-std=c99", "-O2", f"-I{fmi_header_dir()}", str(DRIVER),
                  "-o", str(exe), *libs], what=f"compiling the test importer for {target.fmi3}",
                 compiler=str(zig_or_skip()))
    return exe


def outputs(lines: list[str]) -> list[list[float]]:
    """The ``y ...`` lines of a driver's ``run`` mode as numbers."""
    return [[float(v) for v in line.split()[1:]] for line in lines if line.startswith("y ")]


class Wine:
    """One Wine prefix for the session (its first start takes seconds); ``run`` a Windows program in it."""

    def __init__(self, prefix: Path):
        self.env = {**os.environ, "WINEPREFIX": str(prefix), "WINEDEBUG": "-all",
                    "WINEDLLOVERRIDES": "mscoree,mshtml="}  # no Mono or Gecko: nothing to download
        self.env.pop("DISPLAY", None)
        subprocess.run(["wine", "wineboot", "--init"], env=self.env, capture_output=True, timeout=300, check=False)
        subprocess.run(["wineserver", "-w"], env=self.env, capture_output=True, timeout=300, check=False)

    def run(self, exe: Path, *args: str) -> subprocess.CompletedProcess:
        return subprocess.run(["wine", str(exe), *args], env=self.env, capture_output=True, text=True, timeout=300)

    @staticmethod
    def path(path: Path) -> str:
        """Wine maps / to drive Z:."""
        return "Z:" + str(Path(path).resolve()).replace("/", "\\")

    def close(self) -> None:
        subprocess.run(["wineserver", "-k"], env=self.env, capture_output=True, timeout=60, check=False)


def wine_or_skip() -> None:
    if not (shutil.which("wine") and shutil.which("wineserver")):
        pytest.skip("Wine is not installed (Debian package 'wine'; make setup installs it where apt-get runs as root)")


def qemu_or_skip() -> list[str]:
    """``qemu-aarch64 -L <sysroot>``: runs an aarch64 glibc program."""
    if not shutil.which("qemu-aarch64"):
        pytest.skip("QEMU user mode is not installed (Debian package 'qemu-user'; make setup installs it as root)")
    if not (AARCH64_SYSROOT / "lib" / "ld-linux-aarch64.so.1").exists():
        pytest.skip(f"no aarch64 C library at {AARCH64_SYSROOT} (Debian package 'libc6-arm64-cross'; make setup "
                    f"installs it as root)")
    return ["qemu-aarch64", "-L", str(AARCH64_SYSROOT)]


# ---- binary formats ---------------------------------------------------------------------------

ELF_MACHINES = {62: "x86_64", 183: "aarch64"}
MACHO_CPUS = {0x01000007: "x86_64", 0x0100000C: "aarch64"}


def binary_format(path: Path) -> tuple[str, str]:
    """("ELF shared object" | "PE DLL" | "Mach-O dylib", architecture) from the file's header."""
    data = Path(path).read_bytes()
    if data[:4] == b"\x7fELF":
        e_type, e_machine = struct.unpack_from("<HH", data, 16)
        return ("ELF shared object" if e_type == 3 else f"ELF type {e_type}", ELF_MACHINES.get(e_machine, "?"))
    if data[:2] == b"MZ":
        pe = struct.unpack_from("<I", data, 0x3C)[0]
        machine, characteristics = struct.unpack_from("<H", data, pe + 4)[0], struct.unpack_from("<H", data, pe + 22)[0]
        kind = "PE DLL" if data[pe:pe + 4] == b"PE\0\0" and characteristics & 0x2000 else "PE"
        return kind, {0x8664: "x86_64", 0xAA64: "aarch64"}.get(machine, "?")
    magic, cpu, _, filetype = struct.unpack_from("<IiiI", data, 0)
    if magic == 0xFEEDFACF:
        return ("Mach-O dylib" if filetype == 6 else f"Mach-O type {filetype}", MACHO_CPUS.get(cpu, "?"))
    return "unknown", "?"


def macho_exports(path: Path) -> tuple[set[str], bool]:
    """The external symbols a 64-bit Mach-O library defines and exports, and whether it is code-signed."""
    data = Path(path).read_bytes()
    ncmds = struct.unpack_from("<I", data, 16)[0]
    offset, exported, signed = 32, set(), False
    for _ in range(ncmds):
        cmd, size = struct.unpack_from("<II", data, offset)
        if cmd == 0x1D:  # LC_CODE_SIGNATURE
            signed = True
        if cmd == 0x2:  # LC_SYMTAB
            symoff, nsyms, stroff, _ = struct.unpack_from("<IIII", data, offset + 8)
            for k in range(nsyms):
                strx, n_type = struct.unpack_from("<IB", data, symoff + 16 * k)
                if n_type & 0x01 and not n_type & 0x10 and n_type & 0x0E == 0x0E:  # N_EXT, not N_PEXT, N_SECT
                    name = data[stroff + strx:data.index(b"\0", stroff + strx)].decode()
                    exported.add(name[1:] if name.startswith("_") else name)
        offset += size
    return exported, signed


# ---- the shipped sources as strict C ------------------------------------------------------------

def compile_strict_c99(sources: Path, files: list[str], out: Path) -> None:
    """Compile each source for x86_64 Windows as C99 with GNU extensions and VLAs as errors (MSVC has neither);
    the objects go to the folder ``out``."""
    zig = zig_or_skip()
    for name in files:
        run_compiler(["cc", "-target", PLATFORMS["x86_64-windows"].zig_target, "-c", "-std=c99", "-pedantic-errors",
                      "-Werror=vla", "-Wall", "-Werror", "-Wno-strict-prototypes",  # fmi3FunctionTypes.h has `()`
                      f"-I{sources}", str(sources / name),
                      "-o", str(out / f"{name}.obj")], what=f"strict C99 check of {name}", compiler=str(zig))
