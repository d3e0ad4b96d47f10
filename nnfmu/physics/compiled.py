"""Compile a CasADi Function to a shared library once, and reuse it from a cache.

Data generation calls the same RK4 step millions of times; compiled C runs it
roughly ten times faster than CasADi's virtual machine. The build goes through
the one C build service :mod:`nnfmu.cbuild`: the compiler is ``$CC`` (a command:
``CC="ccache gcc"`` works) or the first of cc, gcc, clang; the library is keyed
by a hash of the generated C code, the flags, the compiler and the CPU, stored
under ``$NNFMU_CACHE_DIR`` or ``$XDG_CACHE_HOME/nnfmu`` (default ``~/.cache/nnfmu``),
and written atomically. Without a working compiler, or if compiling fails, the
Function is returned uncompiled with a one-line warning: slower, same numbers.
"""

from __future__ import annotations

import os
import tempfile
import warnings
from pathlib import Path

import casadi as ca

from nnfmu import cbuild
from nnfmu.cbuild import cache_dir
from nnfmu.errors import FmuBuildError

__all__ = ["cache_dir", "compile_function"]

_CFLAGS = ("-O2", "-shared", "-fPIC")


def compile_function(fn: ca.Function, *, compiler: str | None = None) -> ca.Function:
    """Return ``fn`` compiled to C and loaded with :func:`casadi.external` (same ports, same results).

    Parameters
    ----------
    fn : casadi.Function
        Any code-generable Function (SX or MX without cvodes/idas).
    compiler : str, optional
        C compiler command (``"ccache gcc"``); default ``$CC``, else the first of cc, gcc, clang.
    """
    with tempfile.TemporaryDirectory(prefix="nnfmu_cg_") as tmp:
        c_file = Path(tmp) / f"{fn.name()}.c"
        gen = ca.CodeGenerator(c_file.name, {"with_header": False})
        gen.add(fn)
        gen.generate(tmp + os.sep)
        code = c_file.read_text()
    try:
        target = cbuild.build_cached(fn.name(), code, flags=_CFLAGS, compiler=compiler,
                                     what=f"compiling {fn.name()}")
    except (FmuBuildError, OSError) as exc:
        warnings.warn(f"{fn.name()} runs uncompiled (slower, same values): {str(exc).splitlines()[0]}",
                      RuntimeWarning, stacklevel=2)
        return fn
    return ca.external(fn.name(), str(target))
