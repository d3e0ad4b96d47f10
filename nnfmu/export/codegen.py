"""CasADi ``(init, step)`` -> C source, with a unique symbol prefix and the matrix-product speed patch.

CasADi's generated C is correct but slow for dense networks: 92 % of a GRU-64
step sits in its dense matrix-product helper, which walks the weight matrix
row-wise (stride ``nrow``) and gives the compiler no ``restrict``, so
``gcc -O3`` cannot vectorise it (see ``shared/reference/step-speed.md``).
:func:`patch_source` replaces that helper with one whose inner loop runs over
the contiguous row index with ``restrict`` pointers. Every element of the
result still adds its products in CasADi's order, so results are
bit-identical to CasADi's own evaluation; only the loop nest is interchanged.

The patch also
- marks the model functions of code with dense matrix products for runtime
  dispatch (GCC/Clang ``target_clones`` on x86-64 glibc): one portable binary
  that uses AVX2 where the CPU has it, without FMA, so results stay
  bit-identical;
- hides every symbol of the generated file inside the FMU's shared library,
  and all of them carry a per-model prefix, so that two FMUs loaded into one
  process cannot clash.
"""

from __future__ import annotations

import hashlib
import re
import warnings
from dataclasses import dataclass
from pathlib import Path

import casadi as ca

from nnfmu.errors import FmuBuildError
from nnfmu.system import CasadiModel

MODEL_C = "model_casadi.c"
MODEL_H = "model_casadi.h"

_PREAMBLE = r"""
/* ---- nnfmu: added after CasADi's output (nnfmu/export/codegen.py) ---- */
/* Keep every symbol of this file inside the FMU's library; the FMI wrapper exports the FMI API. */
#ifndef CASADI_SYMBOL_EXPORT
#define CASADI_SYMBOL_EXPORT
#endif
#if defined(__GNUC__) && !defined(_WIN32) && !defined(__CYGWIN__)
#pragma GCC visibility push(hidden)
#define NNFMU_VISIBILITY_PUSHED
#endif
#if defined(__cplusplus)
#define NNFMU_RESTRICT __restrict
#elif defined(__STDC_VERSION__) && __STDC_VERSION__ >= 199901L
#define NNFMU_RESTRICT restrict
#elif defined(__GNUC__) || defined(_MSC_VER)
#define NNFMU_RESTRICT __restrict
#else
#define NNFMU_RESTRICT
#endif
/* Runtime dispatch: an AVX2 clone of each model function next to the baseline one (no FMA, so the
   results are the same bits). Only where the toolchain and the C library support it. */
#if defined(__x86_64__) && defined(__linux__) && defined(__GLIBC__) && defined(__has_attribute)
#if __has_attribute(target_clones)
#define NNFMU_CLONES __attribute__((target_clones("avx2", "default")))
#endif
#endif
#ifndef NNFMU_CLONES
#define NNFMU_CLONES
#endif
/* ---- end of nnfmu preamble ---- */
"""

_EPILOGUE = """
#ifdef NNFMU_VISIBILITY_PUSHED
#pragma GCC visibility pop
#endif
"""

_DENSE_KERNEL = r"""/* nnfmu: CasADi's dense product z += x*y (tr: z += x'*y) with the loops reordered so that the
   innermost index is contiguous and the pointers are restrict-qualified: gcc -O3 vectorises it.
   Each z element still adds its products for k = 0, 1, ... in CasADi's order: bit-identical. */
void casadi_mtimes_dense(const casadi_real* NNFMU_RESTRICT x, casadi_int nrow_x, casadi_int ncol_x,
    const casadi_real* NNFMU_RESTRICT y, casadi_int ncol_y, casadi_real* NNFMU_RESTRICT z, casadi_int tr) {
  casadi_int i, j, k;
  if (tr) {
    for (i=0; i<ncol_y; ++i) {
      for (j=0; j<ncol_x; ++j) {
        casadi_real acc = z[j + i*ncol_x];
        for (k=0; k<nrow_x; ++k) acc += x[k + j*nrow_x] * y[k + i*nrow_x];
        z[j + i*ncol_x] = acc;
      }
    }
  } else {
    for (i=0; i<ncol_y; ++i) {
      casadi_real* NNFMU_RESTRICT zi = z + i*nrow_x;
      for (k=0; k<ncol_x; ++k) {
        const casadi_real* NNFMU_RESTRICT xk = x + k*nrow_x;
        const casadi_real yk = y[k + i*ncol_x];
        for (j=0; j<nrow_x; ++j) zi[j] += xk[j] * yk;
      }
    }
  }
}
"""

_DENSE_HELPER = re.compile(r"^void casadi_mtimes_dense\(.*?^}\n", re.S | re.M)
_MODEL_FUNCTION = re.compile(r"^static int (casadi_f\d+)\(", re.M)
_MUTABLE_STATIC = re.compile(r"^\s*static\s+(?!const\b)[^(\n]*[;=]", re.M)
_INCLUDE = re.compile(r"^#include .*\n", re.M)


@dataclass(frozen=True)
class GeneratedCode:
    """What :func:`generate_c` wrote: file names (in the sources folder) and the C entry points."""

    c_file: str
    h_file: str
    entry_points: dict[str, str]
    n_x: int


def symbol_prefix(model: CasadiModel) -> str:
    """``nnfmu_<name>_<hash>``: unique per model content, so two different FMUs never share a C symbol."""
    digest = hashlib.sha256()
    for part in (model.init.serialize(), model.step.serialize(), repr(model.spec)):
        digest.update(part.encode())
    # CasADi function names allow no leading, trailing or doubled underscores
    name = re.sub(r"_+", "_", model.spec.name).strip("_") or "model"
    return f"nnfmu_{name}_{digest.hexdigest()[:10]}"


def _renamed(fn: ca.Function, name: str) -> ca.Function:
    """``fn`` under a new C name, its expression graph inlined (no extra call layer in the C code)."""
    if fn.is_a("SXFunction"):
        args = fn.sx_in()
        outs = fn.call(args)
    else:
        args = fn.mx_in()
        outs = fn.call(args, fn.is_a("MXFunction"), False)
    return ca.Function(name, args, outs, fn.name_in(), fn.name_out())


def patch_source(source: str, *, speed_patch: bool = True) -> str:
    """Apply the preamble (symbol hiding) and, with ``speed_patch``, the vectorisable dense kernel and
    runtime dispatch to CasADi's C output."""
    includes = list(_INCLUDE.finditer(source))
    if not includes:
        raise FmuBuildError("CasADi's generated C has no #include line; nnfmu cannot patch it "
                            "(is the installed CasADi the pinned 3.8.x?)")
    cut = includes[-1].end()
    source = source[:cut] + _PREAMBLE + source[cut:] + _EPILOGUE
    if not speed_patch or "casadi_mtimes_dense(" not in source:
        return source  # scalar (SX) code: nothing to vectorise, and clones would only double compile time
    source, n = _DENSE_HELPER.subn(lambda _: _DENSE_KERNEL, source, count=1)
    if n != 1:
        warnings.warn("CasADi's dense matrix-product helper has an unexpected shape; the FMU is "
                      "correct but its step is not vectorised (expected CasADi 3.8.x)", stacklevel=3)
    return _MODEL_FUNCTION.sub(r"NNFMU_CLONES\nstatic int \1(", source)


def generate_c(model: CasadiModel, directory: Path, prefix: str, *, speed_patch: bool = True) -> GeneratedCode:
    """Write ``model_casadi.c``/``.h`` for ``model`` into ``directory``; entry points are ``<prefix>_entry_*``.

    Raises FmuBuildError if CasADi cannot generate C for the functions, or if
    the generated code keeps mutable static state (which would break several
    instances running side by side).
    """
    names = {"NNFMU_INIT": f"{prefix}_entry_init", "NNFMU_STEP": f"{prefix}_entry_step"}
    generator = ca.CodeGenerator(MODEL_C, {"with_header": True, "verbose": False, "prefix": prefix})
    try:
        generator.add(_renamed(model.init, names["NNFMU_INIT"]))
        generator.add(_renamed(model.step, names["NNFMU_STEP"]))
        generator.generate(str(directory) + "/")
    except RuntimeError as exc:
        raise FmuBuildError(
            f"CasADi cannot generate C code for model {model.spec.name!r}: {exc}; build init and step "
            f"from code-generatable operations (no external or plugin functions)") from exc
    path = Path(directory) / MODEL_C
    source = patch_source(path.read_text(encoding="utf-8"), speed_patch=speed_patch)
    mutable = _MUTABLE_STATIC.findall(source)
    if mutable:
        raise FmuBuildError(
            f"the generated C for {model.spec.name!r} keeps mutable static state ({mutable[0].strip()!r}), "
            f"so FMU instances would share it; use CasADi functions without memory objects")
    path.write_text(source, encoding="utf-8")
    entry = dict(names)
    entry.update({f"{macro}_WORK": f"{symbol}_work" for macro, symbol in names.items()})
    return GeneratedCode(MODEL_C, MODEL_H, entry, model.n_x)
