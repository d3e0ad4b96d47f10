"""The one C build service: find the compiler, compile with a timeout, cache by content, load.

Every place that compiles C (the FMU binaries in :mod:`nnfmu.export`, the compiled
physics of :mod:`nnfmu.physics.compiled`, the recurrent free run of
:mod:`nnfmu.training.compiled_rollout`, the torch bridge of
:mod:`nnfmu.hybrid.compiled_torch`) goes through :func:`run_compiler`, the only
function in the package that starts the C compiler (through ``_run``). It imports nothing but
:mod:`nnfmu.errors`, so every layer may use it::

    lib = load(build_cached("rollout_double", source, flags=("-O3", "-fPIC", "-shared")))

A compiler is a command, not a path: ``$CC="ccache gcc"`` or ``compiler="zig cc"`` is split
with :func:`shlex.split`, and only its first word is looked up on ``PATH``. A failure is
one :class:`~nnfmu.errors.FmuBuildError` line that ends with the compiler's first error
line; the compiler's whole output is the error's ``.stderr``. Libraries are cached in
:func:`cache_dir` under a hash of the source, the flags, the compiler command and the CPU
(``-march=native`` depends on it), and written atomically (built under a temporary name,
then renamed), so that parallel runs never load a half-written file.
"""

from __future__ import annotations

import ctypes
import functools
import hashlib
import os
import platform
import shlex
import shutil
import signal
import subprocess
import sys
import tempfile
from pathlib import Path
from typing import Sequence, Union

from nnfmu.errors import FmuBuildError

__all__ = ["DEFAULT_FLAGS", "GCC_ONLY_FLAGS", "CANDIDATES", "compiler_argv", "find_compiler",
           "run_compiler", "compile_shared_library", "shared_library_suffix", "cache_dir", "cpu_id",
           "build_cached", "load"]

#: ``-O3`` is needed for gcc 12 to vectorise the matrix kernel; ``-ffp-contract=off`` keeps a*b+c
#: unfused on FMA targets, so the code computes the same bits as CasADi's own evaluation.
DEFAULT_FLAGS = ("-O3", "-std=c99", "-ffp-contract=off", "-fPIC", "-fvisibility=hidden")
#: Flags that only GCC takes; :func:`run_compiler` leaves them out for any other compiler.
GCC_ONLY_FLAGS = frozenset({"-fno-tree-loop-distribute-patterns"})
#: Looked for on PATH, in this order, when neither ``compiler`` nor ``$CC`` names one.
CANDIDATES = ("cc", "gcc", "clang")
#: Seconds one compiler run may take before it is stopped.
TIMEOUT_S = 600.0

Compiler = Union[str, Sequence[str], None]


def compiler_argv(compiler: Compiler = None) -> tuple[str, ...]:
    """The compiler's command words, its program resolved on PATH: ``("/usr/bin/ccache", "gcc")``.

    ``compiler`` is a command string (split with :func:`shlex.split`: ``"ccache gcc"``), a sequence
    of words taken as they are (a path with spaces: ``[zig_path, "cc"]``), or None for ``$CC``, else the
    first of :data:`CANDIDATES` on PATH. Raises FmuBuildError naming what was looked for when none is found.
    """
    if compiler is not None and not isinstance(compiler, str):
        wanted = [tuple(compiler)]
    elif compiler or os.environ.get("CC", "").strip():
        wanted = [tuple(shlex.split(compiler or os.environ["CC"]))]
    else:
        wanted = [(name,) for name in CANDIDATES]
    for words in wanted:
        found = shutil.which(words[0]) if words and words[0] else None
        if found:
            return (found, *words[1:])
    origin = "the compiler you asked for" if compiler else ("$CC" if os.environ.get("CC") else "PATH")
    raise FmuBuildError(
        f"no C compiler found: looked for {', '.join(repr(shlex.join(w)) for w in wanted)} ({origin}); "
        f"install one (e.g. 'apt-get install gcc'), or set CC / pass compiler='/path/to/cc'")


def find_compiler(compiler: Compiler = None) -> str:
    """:func:`compiler_argv` as one command string (``"/usr/bin/ccache gcc"``), for messages and cache keys."""
    return shlex.join(compiler_argv(compiler))


@functools.lru_cache(maxsize=None)
def _is_gcc(argv: tuple[str, ...]) -> bool:
    """Whether the compiler is GCC: its preprocessor defines ``__GNUC__`` and not ``__clang__``.
    A compiler that cannot answer counts as not GCC."""
    try:
        done = _run([*argv, "-dM", "-E", "-x", "c", os.devnull], None, 60.0)
    except (OSError, subprocess.TimeoutExpired):
        return False
    macros = done.stdout.split()
    return done.returncode == 0 and "__GNUC__" in macros and "__clang__" not in macros


def first_error_line(stderr: str) -> str:
    """The line of the compiler's output that says what went wrong: the first naming an error, else the first."""
    lines = [line.strip() for line in stderr.splitlines() if line.strip()]
    return next((line for line in lines if "error" in line.lower()), lines[0] if lines else "no output")


def run_compiler(args: Sequence[str], *, what: str, compiler: Compiler = None,
                 cwd: str | Path | None = None, timeout_s: float = TIMEOUT_S) -> subprocess.CompletedProcess:
    """Run ``<compiler> args``, the one place nnfmu starts the C compiler.

    ``what`` names the job for the message ("compiling the FMU binary of 'valve' for linux64"). Raises
    FmuBuildError in one line when the compiler is missing, fails (with its first error line; the whole
    output is ``.stderr``) or runs longer than ``timeout_s`` seconds.
    """
    argv = compiler_argv(compiler)
    if not _is_gcc(argv):
        args = [a for a in args if a not in GCC_ONLY_FLAGS]
    command = [*argv, *args]
    try:
        done = _run(command, cwd, timeout_s)
    except subprocess.TimeoutExpired as exc:
        raise FmuBuildError(f"{what}: the C compiler did not finish within {timeout_s:g} s "
                            f"({shlex.join(argv)}); try again with fewer parallel jobs") from exc
    except OSError as exc:
        raise FmuBuildError(f"{what}: cannot run the C compiler {shlex.join(argv)!r} ({exc}); "
                            f"check the installation or set CC") from exc
    if done.returncode != 0:
        stderr = done.stderr.strip() or done.stdout.strip()
        program = shlex.join([Path(argv[0]).name, *argv[1:]])
        error = FmuBuildError(f"{what} failed: {program} exited with status {done.returncode}: "
                              f"{first_error_line(stderr)}")
        error.stderr = stderr
        error.command = command
        raise error
    return done


def _run(command: list[str], cwd: str | Path | None, timeout_s: float) -> subprocess.CompletedProcess:
    """``subprocess.run`` in a session of its own, so that a timeout stops the compiler's children too
    (``cc1``, or whatever a wrapper in ``$CC`` started), not only the command."""
    with subprocess.Popen(command, cwd=cwd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                          start_new_session=True) as proc:
        try:
            out, err = proc.communicate(timeout=timeout_s)
        except subprocess.TimeoutExpired:
            if hasattr(os, "killpg"):
                os.killpg(proc.pid, signal.SIGKILL)
            else:
                proc.kill()
            proc.communicate()
            raise
    return subprocess.CompletedProcess(command, proc.returncode, out, err)


def shared_library_suffix() -> str:
    """``.so``, ``.dylib`` or ``.dll``: this platform's shared-library suffix."""
    return {"win32": ".dll", "darwin": ".dylib"}.get(sys.platform, ".so")


def compile_shared_library(sources: Sequence[Path], output: Path, *, include_dirs: Sequence[Path] = (),
                           flags: Sequence[str] = DEFAULT_FLAGS, compiler: Compiler = None,
                           what: str = "compiling a shared library", libs: Sequence[str] = ("-lm",)) -> Path:
    """Compile C ``sources`` into the shared library ``output`` (linked with ``libs``); return ``output``."""
    output.parent.mkdir(parents=True, exist_ok=True)
    args = [*flags, "-shared", *(f"-I{d}" for d in include_dirs), *map(str, sources), "-o", str(output), *libs]
    run_compiler(args, what=what, compiler=compiler)
    return output


def cache_dir() -> Path:
    """The folder of compiled libraries: ``$NNFMU_CACHE_DIR/compiled``, else ``$XDG_CACHE_HOME/nnfmu/compiled``
    (default ``~/.cache/nnfmu/compiled``); created on first build."""
    root = os.environ.get("NNFMU_CACHE_DIR")
    if not root:
        root = os.path.join(os.environ.get("XDG_CACHE_HOME") or os.path.expanduser("~/.cache"), "nnfmu")
    return Path(root) / "compiled"


@functools.lru_cache(maxsize=None)
def cpu_id() -> str:
    """What ``-march=native`` depends on: the machine, CPU model and flags (a shared cache may serve others)."""
    try:
        text = Path("/proc/cpuinfo").read_text()
    except OSError:
        return f"{platform.machine()}\n{platform.processor()}"
    lines = [line for line in text.splitlines() if line.startswith(("model name", "flags"))]
    return "\n".join([platform.machine(), *sorted(set(lines))])


def build_cached(name: str, source: str, *, flags: Sequence[str] = DEFAULT_FLAGS,
                 link_choices: Sequence[Sequence[str]] = (("-lm",),), compiler: Compiler = None,
                 what: str | None = None) -> Path:
    """The shared library of C ``source``, compiled once and then taken from :func:`cache_dir`.

    ``name`` starts the file name (``<name>_<hash><suffix>``); the hash covers the source, ``flags``,
    ``link_choices``, the compiler command and :func:`cpu_id`. ``link_choices`` lists link options to try in order
    (``(("-lmvec", "-lm"), ("-lm",))``: the first that links is kept). ``flags`` must make a shared
    library (``-shared -fPIC``). Raises FmuBuildError (from :func:`run_compiler`) when no option builds.
    """
    cc = find_compiler(compiler)
    key = hashlib.sha256("\n\0".join([source, cc, shlex.join(flags), repr(tuple(map(tuple, link_choices))),
                                      cpu_id()]).encode()).hexdigest()[:20]
    target = cache_dir() / f"{name}_{key}{shared_library_suffix()}"
    if target.exists():
        return target
    target.parent.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(prefix=f".{name}_", dir=target.parent) as tmp:
        c_file, built = Path(tmp) / f"{name}.c", Path(tmp) / target.name
        c_file.write_text(source)
        for i, link in enumerate(link_choices):
            try:
                run_compiler([*flags, str(c_file), "-o", str(built), *link], what=what or f"compiling {name}",
                             compiler=compiler)
                break
            except FmuBuildError:
                if i == len(link_choices) - 1:
                    raise
        os.replace(built, target)  # atomic: a parallel run never loads a half-written library
    return target


def load(library: Path) -> ctypes.CDLL:
    """The shared library at ``library``, loaded with :mod:`ctypes`; FmuBuildError if it cannot be loaded."""
    try:
        return ctypes.CDLL(str(library))
    except OSError as exc:
        raise FmuBuildError(f"cannot load the compiled library {library} ({exc}); remove it to rebuild it") from exc
