"""The FMU binaries' build profiles: compiler flags over the one C build service :mod:`nnfmu.cbuild`.

Every compile (the FMU's binary, the benchmark drivers) goes through
:func:`nnfmu.cbuild.run_compiler`, which raises :class:`nnfmu.errors.FmuBuildError` in one line, with the
compiler's whole stderr as ``.stderr``, when the compiler is missing, fails or hangs. Flags that only GCC
understands (:data:`nnfmu.cbuild.GCC_ONLY_FLAGS`) reach GCC alone: clang and ``zig cc`` reject them.
"""

from __future__ import annotations

from nnfmu.cbuild import DEFAULT_FLAGS

__all__ = ["PROFILE_FLAGS"]

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
