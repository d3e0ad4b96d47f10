"""Compile a CasADi Function to a shared library once, and reuse it from a cache.

Data generation calls the same RK4 step millions of times; compiled C runs it
roughly ten times faster than CasADi's virtual machine. The library is keyed
by a hash of the generated C code and the compiler command, stored under
``$NNFMU_CACHE_DIR`` or ``$XDG_CACHE_HOME/nnfmu`` (default ``~/.cache/nnfmu``),
and written atomically (compiled to a temporary name, then renamed), so that
parallel runs never load a half-written file. Without a working compiler the
Function is returned uncompiled, with a warning: slower, same numbers.
"""

from __future__ import annotations

import hashlib
import os
import shutil
import subprocess
import tempfile
import warnings
from pathlib import Path

import casadi as ca

__all__ = ["cache_dir", "compile_function"]

_CFLAGS = ("-O2", "-shared", "-fPIC")


def cache_dir() -> Path:
    """The folder holding compiled libraries (created on first use)."""
    root = os.environ.get("NNFMU_CACHE_DIR")
    if not root:
        root = os.path.join(os.environ.get("XDG_CACHE_HOME") or os.path.expanduser("~/.cache"), "nnfmu")
    return Path(root) / "compiled"


def compile_function(fn: ca.Function, *, compiler: str | None = None) -> ca.Function:
    """Return ``fn`` compiled to C and loaded with :func:`casadi.external` (same ports, same results).

    Parameters
    ----------
    fn : casadi.Function
        Any code-generable Function (SX or MX without cvodes/idas).
    compiler : str, optional
        C compiler executable; default ``$CC`` or ``gcc``.
    """
    compiler = compiler or os.environ.get("CC", "gcc")
    if shutil.which(compiler) is None:
        warnings.warn(f"C compiler {compiler!r} not found; running {fn.name()} uncompiled (slower)",
                      RuntimeWarning, stacklevel=2)
        return fn
    with tempfile.TemporaryDirectory(prefix="nnfmu_cg_") as tmp:
        c_file = Path(tmp) / f"{fn.name()}.c"
        gen = ca.CodeGenerator(c_file.name, {"with_header": False})
        gen.add(fn)
        gen.generate(tmp + os.sep)
        code = c_file.read_bytes()
        key = hashlib.sha256(code + " ".join((compiler,) + _CFLAGS + (ca.__version__,)).encode()).hexdigest()[:20]
        target = cache_dir() / f"{fn.name()}_{key}.so"
        if not target.exists():
            _build(compiler, c_file, target)
    if not target.exists():  # the build failed and warned
        return fn
    return ca.external(fn.name(), str(target))


def _build(compiler: str, c_file: Path, target: Path) -> None:
    try:
        target.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp_so = tempfile.mkstemp(prefix=f".{target.stem}.", suffix=".so.tmp", dir=target.parent)
        os.close(fd)
    except OSError as exc:
        warnings.warn(f"cannot write to the cache folder {target.parent} ({exc}); running uncompiled",
                      RuntimeWarning, stacklevel=3)
        return
    try:
        proc = subprocess.run([compiler, *_CFLAGS, str(c_file), "-o", tmp_so, "-lm"],
                              capture_output=True, text=True)
        if proc.returncode != 0:
            warnings.warn(f"compiling {c_file.name} failed; running uncompiled (slower):\n{proc.stderr[-2000:]}",
                          RuntimeWarning, stacklevel=3)
            return
        os.replace(tmp_so, target)
    finally:
        if os.path.exists(tmp_so):
            os.remove(tmp_so)
