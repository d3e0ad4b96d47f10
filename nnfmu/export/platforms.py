"""Binaries for several platforms in one FMU: the host's with the system C compiler, the others cross-compiled.

Cross compilation uses Zig's clang-based ``zig cc`` from the ``ziglang`` package on PyPI
(``pip install 'nnfmu[cross]'``), which brings a C library for each target (glibc stubs,
mingw-w64, macOS's libSystem stubs), so one Linux machine builds every binary. The
platform names are those each FMI version uses for its ``binaries/`` folder:

=================  ===========  ================  ==========================
platform           FMI 2        FMI 3             zig target
=================  ===========  ================  ==========================
Linux x86-64       linux64      x86_64-linux      x86_64-linux-gnu.2.17
Windows x86-64     win64        x86_64-windows    x86_64-windows-gnu
macOS x86-64       darwin64     x86_64-darwin     x86_64-macos.10.15
Linux ARM64        aarch64-linux (no FMI 2 name)  aarch64-linux-gnu.2.17
macOS ARM64        aarch64-darwin (no FMI 2 name) aarch64-macos.11.0
=================  ===========  ================  ==========================

FMI 2.0 names x86 platforms only; for ARM64 nnfmu uses the FMI 3 tuple in FMI 2 FMUs
too, as fmpy does when it lists an FMU's platforms. ``--platforms`` accepts either
spelling, ``host`` (the default: this machine only) and ``all``. Cross-compiled binaries
get the build profile's portable flags only: flags chosen for the host's machine
(``-march``, ``-m...``) are not passed on, and the fast profile's x86 clones are guarded in
the C itself (x86-64 glibc only, where ifunc dispatches them; the portable code elsewhere).
"""

from __future__ import annotations

import os
import platform as _platform
import shutil
import sys
import tempfile
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Sequence

from nnfmu.errors import ConfigError, FmuBuildError
from nnfmu import cbuild

__all__ = ["Platform", "PLATFORMS", "host_platform", "parse_platforms", "zig_executable", "build_binaries"]


@dataclass(frozen=True)
class Platform:
    """One binary platform: its FMI 3 platform tuple, its FMI 2 folder name, Zig's target and the library suffix."""

    fmi3: str
    fmi2: str
    zig_target: str
    suffix: str

    def folder(self, fmi_version: int) -> str:
        """The ``binaries/<folder>`` name for this FMI version."""
        return self.fmi2 if fmi_version == 2 else self.fmi3


PLATFORMS = {p.fmi3: p for p in (
    Platform("x86_64-linux", "linux64", "x86_64-linux-gnu.2.17", ".so"),
    Platform("x86_64-windows", "win64", "x86_64-windows-gnu", ".dll"),
    Platform("x86_64-darwin", "darwin64", "x86_64-macos.10.15", ".dylib"),
    Platform("aarch64-linux", "aarch64-linux", "aarch64-linux-gnu.2.17", ".so"),
    Platform("aarch64-darwin", "aarch64-darwin", "aarch64-macos.11.0", ".dylib"),
)}
_ALIASES = {**{p.fmi2: p.fmi3 for p in PLATFORMS.values()}, **{t: t for t in PLATFORMS}}


def host_platform() -> Platform:
    """The platform this Python runs on (raises FmuBuildError on an unsupported one)."""
    machine = {"amd64": "x86_64", "arm64": "aarch64"}.get(_platform.machine().lower(), _platform.machine().lower())
    system = {"linux": "linux", "darwin": "darwin", "win32": "windows"}.get(sys.platform, sys.platform)
    key = f"{machine}-{system}"
    if key not in PLATFORMS:
        raise FmuBuildError(f"building FMUs on {key!r} is not supported; use one of {', '.join(PLATFORMS)}")
    return PLATFORMS[key]


def parse_platforms(names: str | Sequence[str] | None) -> tuple[Platform, ...]:
    """Platforms from ``"linux64,win64"``, a sequence of names, ``"all"`` or ``None``/``"host"`` (this machine).

    Raises ConfigError for an unknown name, listing the valid ones.
    """
    if names is None:
        names = ["host"]
    elif isinstance(names, str):
        names = [n.strip() for n in names.split(",") if n.strip()]
    chosen: list[Platform] = []
    for name in names:
        if name == "all":
            picked = list(PLATFORMS.values())
        elif name == "host":
            picked = [host_platform()]
        elif name in _ALIASES:
            picked = [PLATFORMS[_ALIASES[name]]]
        else:
            valid = ", ".join(["host", "all", *sorted(_ALIASES)])
            raise ConfigError(f"unknown platform {name!r}; choose from {valid} (comma-separated)")
        chosen += [p for p in picked if p not in chosen]
    if not chosen:
        raise ConfigError("no platform given; pass e.g. --platforms linux64,win64 or --platforms all")
    return tuple(chosen)


def zig_executable() -> Path:
    """The ``zig`` binary of the ``ziglang`` package; ConfigError naming the install command if it is missing."""
    try:
        import ziglang
    except ImportError as exc:
        raise ConfigError("cross-compiling for other platforms needs the Zig toolchain: pip install "
                          "'nnfmu[cross]' (the ziglang package), or build for the host only (--platforms host)") from exc
    zig = Path(ziglang.__file__).parent / ("zig.exe" if sys.platform == "win32" else "zig")
    if not zig.is_file():
        raise ConfigError(f"the ziglang package has no zig executable at {zig}; reinstall it: "
                          f"pip install --force-reinstall ziglang")
    return zig


def portable_flags(flags: Sequence[str]) -> list[str]:
    """``flags`` without the ones chosen for the host's machine (``-march=``, ``-mavx2``, ...)."""
    return [f for f in flags if not f.startswith("-m")]


def cross_compile(target: Platform, sources: Sequence[Path], output: Path, *, include_dirs: Sequence[Path],
                  flags: Sequence[str], what: str) -> Path:
    """Compile ``sources`` into the shared library ``output`` for ``target`` with ``zig cc``."""
    zig = zig_executable()
    output.parent.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(prefix="nnfmu-zig-") as tmp:
        built = Path(tmp) / output.name  # zig also writes .pdb/.lib beside a DLL: keep the library only
        args = ["-target", target.zig_target, *portable_flags(flags), "-shared",
                *(f"-I{d}" for d in include_dirs), *map(str, sources), "-o", str(built), "-lm"]
        cbuild.run_compiler(args, what=what, compiler=[str(zig), "cc"])
        shutil.move(str(built), output)
    return output


def build_binaries(root: Path, model_identifier: str, sources: Sequence[Path], fmi_version: int,
                   targets: Sequence[Platform], *, host_flags: Sequence[str], cross_flags: Sequence[str],
                   compiler_command: str | None = None,
                   on_binary: Callable[[str, float], None] | None = None) -> dict[str, float]:
    """Compile ``sources`` for every platform in ``targets`` into ``root/binaries/<folder>/``.

    The host's binary is built by the system C compiler with ``host_flags`` (and
    ``compiler_command``); the others by ``zig cc`` with ``cross_flags``. The compilers run
    side by side, one per CPU core. Returns ``{folder: seconds}`` (each compile's own wall
    time) and calls ``on_binary(folder, seconds)`` for each binary, in the order of ``targets``.
    """
    host = host_platform()
    if any(t != host for t in targets):
        zig_executable()  # a missing toolchain is one clear error before anything is compiled

    def build(target: Platform) -> tuple[str, float]:
        folder = target.folder(fmi_version)
        out = root / "binaries" / folder / f"{model_identifier}{target.suffix}"
        what = f"compiling the FMU binary of {model_identifier!r} for {folder}"
        start = time.perf_counter()
        if target == host:
            cbuild.compile_shared_library(sources, out, include_dirs=[root / "sources"], flags=host_flags,
                                          compiler=compiler_command, what=what)
        else:
            cross_compile(target, sources, out, include_dirs=[root / "sources"], flags=cross_flags, what=what)
        return folder, time.perf_counter() - start

    seconds: dict[str, float] = {}
    with ThreadPoolExecutor(max_workers=max(1, min(len(targets), os.cpu_count() or 1))) as pool:
        for folder, elapsed in pool.map(build, targets):
            seconds[folder] = elapsed
            if on_binary:
                on_binary(folder, elapsed)
    return seconds
