"""The one choke point where nnfmu runs the system C compiler.

Every compile (the FMU's binary, the benchmark drivers) goes through
:func:`run_compiler`, which raises :class:`nnfmu.errors.FmuBuildError` with
the compiler's stderr attached (as the message's tail and as ``.stderr``)
when the compiler is missing, fails or hangs. Flags that only GCC understands
(:data:`GCC_ONLY_FLAGS`) reach GCC alone: clang and ``zig cc`` reject them.
"""

from __future__ import annotations

import functools
import os
import shlex
import shutil
import subprocess
import sys
from pathlib import Path
from typing import Sequence

from nnfmu.errors import FmuBuildError

#: ``-O3`` is needed for gcc 12 to vectorise the matrix kernel; ``-ffp-contract=off`` keeps a*b+c
#: unfused on FMA targets, so the code computes the same bits as CasADi's own evaluation.
DEFAULT_FLAGS = ("-O3", "-std=c99", "-ffp-contract=off", "-fPIC", "-fvisibility=hidden")
#: Flags of the FMU build profiles (nnfmu.export.codegen): "exact" is DEFAULT_FLAGS; "fast" lets the
#: compiler fuse a*b+c into FMA, and -fno-trapping-math lets it turn the branch-free selects of the
#: vector exp/tanh into blends (the FMU never unmasks floating-point traps, so nothing else changes).
#: The fast profile also asks GCC not to turn loops into memcpy/memset calls: CasADi's code copies and
#: clears short work arrays in loops, which GCC otherwise expands to ``rep movs``/``rep stos``, each
#: with a start-up of tens of cycles; as loops they vectorise (the default GRU and LSTM steps take
#: about 10 % less time, docs/fmu-speed.md).
PROFILE_FLAGS = {
    "exact": DEFAULT_FLAGS,
    "fast": ("-O3", "-std=c99", "-ffp-contract=fast", "-fno-trapping-math", "-fno-tree-loop-distribute-patterns",
             "-fPIC", "-fvisibility=hidden"),
}
#: Flags that only GCC takes; :func:`run_compiler` leaves them out for any other compiler.
GCC_ONLY_FLAGS = frozenset({"-fno-tree-loop-distribute-patterns"})
CANDIDATES = ("cc", "gcc", "clang")


def find_compiler(compiler: str | None = None) -> str:
    """The C compiler to use: ``compiler`` if given, else ``$CC``, else the first of cc, gcc, clang on PATH.

    Raises FmuBuildError naming what was looked for when none is found.
    """
    wanted = [compiler] if compiler else ([os.environ["CC"]] if os.environ.get("CC") else list(CANDIDATES))
    for name in wanted:
        program = shlex.split(name)[0] if name.strip() else ""
        found = shutil.which(program) if program else None
        if found:
            return found
    origin = "the compiler you asked for" if compiler else ("$CC" if os.environ.get("CC") else "PATH")
    raise FmuBuildError(
        f"no C compiler found: looked for {', '.join(map(repr, wanted))} ({origin}); install one "
        f"(e.g. 'apt-get install gcc'), or set CC / pass compiler='/path/to/cc'")


@functools.lru_cache(maxsize=None)
def is_gcc(cc: str) -> bool:
    """Whether the compiler ``cc`` (a path, as :func:`find_compiler` returns it) is GCC: its preprocessor
    defines ``__GNUC__`` and not ``__clang__``. A compiler that cannot answer (``zig``, whose C compiler is
    the ``zig cc`` subcommand, is clang) counts as not GCC."""
    try:
        done = subprocess.run([cc, "-dM", "-E", "-x", "c", os.devnull], capture_output=True, text=True,
                              timeout=60)
    except (OSError, subprocess.TimeoutExpired):
        return False
    macros = done.stdout.split()
    return done.returncode == 0 and "__GNUC__" in macros and "__clang__" not in macros


def run_compiler(args: Sequence[str], *, what: str, compiler: str | None = None,
                 cwd: str | Path | None = None, timeout_s: float = 600.0) -> subprocess.CompletedProcess:
    """Run ``<compiler> args``; raise FmuBuildError with the compiler's stderr if it fails.

    ``what`` names the job for the message ("compiling the FMU binary for 'valve'").
    """
    cc = find_compiler(compiler)
    if not is_gcc(cc):
        args = [a for a in args if a not in GCC_ONLY_FLAGS]
    command = [cc, *args]
    try:
        done = subprocess.run(command, cwd=cwd, capture_output=True, text=True, timeout=timeout_s)
    except subprocess.TimeoutExpired as exc:
        raise FmuBuildError(f"{what}: the C compiler did not finish within {timeout_s:g} s; "
                            f"command: {shlex.join(command)}") from exc
    except OSError as exc:
        raise FmuBuildError(f"{what}: cannot run the C compiler {cc!r} ({exc}); "
                            f"check the installation or set CC") from exc
    if done.returncode != 0:
        stderr = done.stderr.strip() or done.stdout.strip()
        error = FmuBuildError(f"{what} failed: {Path(cc).name} exited with status {done.returncode}; "
                              f"command: {shlex.join(command)}\ncompiler stderr:\n{stderr}")
        error.stderr = stderr
        raise error
    return done


def shared_library_suffix() -> str:
    return {"win32": ".dll", "darwin": ".dylib"}.get(sys.platform, ".so")


def compile_shared_library(sources: Sequence[Path], output: Path, *, include_dirs: Sequence[Path] = (),
                           flags: Sequence[str] = DEFAULT_FLAGS, compiler: str | None = None,
                           what: str = "compiling a shared library") -> Path:
    """Compile C ``sources`` into the shared library ``output`` (linked against libm); return ``output``."""
    output.parent.mkdir(parents=True, exist_ok=True)
    args = [*flags, "-shared", *(f"-I{d}" for d in include_dirs), *map(str, sources), "-o", str(output), "-lm"]
    run_compiler(args, what=what, compiler=compiler)
    return output
