"""Zig's warm-up: build once, ahead, what ``zig cc`` builds per target on first use.

``python -m nnfmu.export.prepare_zig`` (``make test`` runs it once) cross-compiles a tiny FMU
and a tiny C program for every platform of :data:`nnfmu.export.platforms.PLATFORMS` other than
the host's, so that neither the test suite nor the first real export pays minutes for it. It
lives apart from :mod:`nnfmu.export.platforms` because it builds whole FMUs (:func:`build_fmu`),
which themselves use the platforms.
"""

from __future__ import annotations

import tempfile
import time
from pathlib import Path
from typing import Callable, Sequence

import casadi as ca

from nnfmu.cbuild import run_compiler
from nnfmu.export.fmu import build_fmu
from nnfmu.export.platforms import PLATFORMS, Platform, host_platform, zig_executable
from nnfmu.system import CasadiModel, SystemSpec

__all__ = ["prepare"]


def prepare(targets: Sequence[Platform] | None = None, echo: Callable[[str], None] = print) -> None:
    """Let Zig build, once, what it builds per target on first use (its C libraries, into its cache).

    The first cross-compile for a target takes minutes (Windows: mingw-w64's C runtime); later ones take
    seconds. This builds a tiny FMU for every cross target and a tiny C program for each (as the test
    suite's importer is), so that ``make test`` and the first real export do not pay it.
    """
    host = host_platform()
    targets = [t for t in (targets or PLATFORMS.values()) if t != host]
    x, u = ca.SX.sym("x"), ca.SX.sym("u")
    step = ca.Function("step", [x, u], [ca.tanh(x) + u, x], ["x", "u"], ["x_next", "y_next"])
    init = ca.Function("init", [x, u], [x], ["y0", "u0"], ["x0"])
    model = CasadiModel(init, step, SystemSpec("prepare", 1.0, ["u"], ["y"]))
    with tempfile.TemporaryDirectory(prefix="nnfmu-zig-prepare-") as tmp:
        program = Path(tmp) / "main.c"
        program.write_text("#include <stdio.h>\nint main(void) { printf(\"ok\\n\"); return 0; }\n", encoding="utf-8")
        for target in targets:
            start = time.perf_counter()
            build_fmu(model, Path(tmp) / f"{target.fmi3}.fmu", platforms=[target.fmi3])
            libs = ["-ldl"] if target.suffix == ".so" else []
            run_compiler(["-target", target.zig_target, "-std=c99", "-O2", str(program), "-o",
                          str(Path(tmp) / f"{target.fmi3}.exe"), *libs],
                         what=f"preparing Zig for {target.fmi3}", compiler=[str(zig_executable()), "cc"])
            echo(f"zig is ready for {target.fmi3} ({time.perf_counter() - start:.0f} s)")


if __name__ == "__main__":  # python -m nnfmu.export.prepare_zig (make test runs it once)
    prepare()
