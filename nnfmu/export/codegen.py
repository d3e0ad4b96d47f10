"""CasADi ``(init, step)`` -> C source: a unique symbol prefix, and the build profile's rewrites.

CasADi's generated C is correct but slow for dense networks: 92 % of a GRU-64
step sits in its dense matrix-product helper, which walks the weight matrix
row-wise (stride ``nrow``) and gives the compiler no ``restrict``, so
``gcc -O3`` cannot vectorise it (measured on the MX code of a GRU-64; docs/fmu-speed.md has
the profiles' step times).
Both profiles replace that helper with one whose inner loop runs over the
contiguous row index with ``restrict`` pointers; every element of the result
still adds its products in CasADi's order.

- ``profile="exact"``: nothing more. Compiled with ``-ffp-contract=off`` and
  dispatched at load time to an AVX2 clone without FMA, the FMU computes the
  same bits as CasADi's own evaluation.
- ``profile="fast"`` (the default; see docs/fmu-speed.md): also inlines
  ``csrc/nnfmu_fast.h``, stores the weight constants as row panels and calls
  their products through its register-blocked kernel (:mod:`.panels`),
  evaluates exp, tanh, fmax and fmin with its branch-free versions, and clones
  the step function for x86-64-v3 (AVX2 + FMA) and x86-64-v4 (AVX-512) next
  to the portable baseline. Compiled with ``-ffp-contract=fast``, each
  product-add rounds once and exp/tanh differ from libm by at most 1 and 3
  ulp: agreement with CasADi and torch becomes a tolerance (docs/fmu-speed.md).
- ``precision="float32"``: CasADi writes the model in ``float``, behind
  float64 entry points (:mod:`.single`).

In every case the symbols of the generated file stay hidden inside the FMU's
shared library and carry a per-model prefix, so that two FMUs loaded into one
process cannot clash.
"""

from __future__ import annotations

import hashlib
import re
import warnings
from dataclasses import dataclass
from importlib import resources
from pathlib import Path

import casadi as ca

from nnfmu.errors import ConfigError, FmuBuildError
from nnfmu.export import panels
from nnfmu.export import float32 as single_precision
from nnfmu.system import CasadiModel

MODEL_C = "model_casadi.c"
MODEL_H = "model_casadi.h"

PROFILES = ("fast", "exact")
PRECISIONS = ("float64", "float32")
_KERNELS = "nnfmu_fast.h"

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
#define casadi_real {real}
#define casadi_int long long int
#define NNFMU_FLOAT32 {float32}
/* Runtime dispatch: {clones_doc}
   Only where the toolchain and the C library support it (GCC or Clang, x86-64, glibc's ifunc);
   elsewhere the portable code alone. */
#if defined(__x86_64__) && defined(__linux__) && defined(__GLIBC__) && defined(__has_attribute)
#if __has_attribute(target_clones)
#define NNFMU_CLONES __attribute__((target_clones({clones})))
#endif
#endif
#ifndef NNFMU_CLONES
#define NNFMU_CLONES
#endif
{kernels}/* ---- end of nnfmu preamble ---- */
"""

_CLONES = {
    "exact": ('"avx2", "default"', "an AVX2 clone of the step function next to the baseline one (no FMA, "
              "so the\n   results are the same bits)."),
    "fast": ('"arch=x86-64-v4", "arch=x86-64-v3", "default"', "AVX-512 and AVX2+FMA clones of the step "
             "function next to the baseline one."),
}

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
STEP_ENTRY = re.compile(r"_(?:entry|f32)_step\(const casadi_real\*\* arg, casadi_real\*\* res, casadi_int\* iw, "
                         r"casadi_real\* w, int mem\)\s*\{\s*return (casadi_f\d+)\(")
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


def _preamble(profile: str, precision: str, kernels: bool) -> str:
    text = ""
    if kernels:
        text = (resources.files("nnfmu.export") / "csrc" / _KERNELS).read_text(encoding="utf-8")
    clones, doc = _CLONES[profile]
    return _PREAMBLE.format(real="float" if precision == "float32" else "double",
                            float32=int(precision == "float32"), clones=clones, clones_doc=doc, kernels=text)


def check_options(profile: str, precision: str) -> None:
    """Raise ConfigError naming the valid values if ``profile`` or ``precision`` is unknown."""
    for what, value, valid in (("profile", profile, PROFILES), ("precision", precision, PRECISIONS)):
        if value not in valid:
            raise ConfigError(f"unknown build {what} {value!r}; choose one of {', '.join(valid)}")


def patch_source(source: str, *, speed_patch: bool = True, profile: str = "fast",
                 precision: str = "float64") -> str:
    """Apply the preamble (symbol hiding) and, with ``speed_patch``, the profile's rewrites (module doc)."""
    check_options(profile, precision)
    includes = list(_INCLUDE.finditer(source))
    if not includes:
        raise FmuBuildError("CasADi's generated C has no #include line; nnfmu cannot patch it "
                            "(is the installed CasADi the pinned 3.8.x?)")
    dense = speed_patch and "casadi_mtimes_dense(" in source
    fast = dense and profile == "fast"
    cut = includes[-1].end()
    source = source[:cut] + _preamble(profile, precision, fast) + source[cut:] + _EPILOGUE
    if not dense:
        return source  # scalar (SX) code: nothing to vectorise, and clones would only double compile time
    source, n = _DENSE_HELPER.subn(lambda _: _DENSE_KERNEL, source, count=1)
    if n != 1:
        warnings.warn("CasADi's dense matrix-product helper has an unexpected shape; the FMU is "
                      "correct but its step is not vectorised (expected CasADi 3.8.x)", stacklevel=3)
    if fast:
        source = panels.use_fast_math(panels.panelize(source, precision))
    step = STEP_ENTRY.search(source)  # clone the step only: init runs once, and each clone costs compile time
    stepped = called_from(source, step.group(1)) if step else None

    def clone(match: re.Match) -> str:
        cloned = stepped is None or match.group(1) in stepped
        return f"{'NNFMU_CLONES' + chr(10) if cloned else ''}static int {match.group(1)}("

    return _MODEL_FUNCTION.sub(clone, source)


MODEL_BODY = re.compile(r"^static int (casadi_f\d+)\((.*?^})\n", re.S | re.M)  # a model function: name, body
CALL = re.compile(r"\b(casadi_f\d+)\(arg")  # a call of a model function in a body


def called_from(source: str, name: str) -> set[str]:
    """``name`` and every model function (``casadi_fN``) of ``source`` that it calls, directly or not.

    The step's callees run in the step's instruction set only if they are cloned too: a hybrid's network
    (a Function called in each RK4 stage) ran in portable SSE2 code when only the step was (issue 36).
    """
    bodies = dict(MODEL_BODY.findall(source))
    todo, seen = [name], set()
    while todo:
        current = todo.pop()
        if current not in seen and current in bodies:
            seen.add(current)
            todo += CALL.findall(bodies[current])
    return seen


def generate_c(model: CasadiModel, directory: Path, prefix: str, *, speed_patch: bool = True,
               profile: str = "fast", precision: str = "float64") -> GeneratedCode:
    """Write ``model_casadi.c``/``.h`` for ``model`` into ``directory``; entry points are ``<prefix>_entry_*``.

    ``profile`` ("fast" or "exact") and ``precision`` ("float64" or "float32") are described in the
    module docstring. The entry points always take and return double.

    Raises FmuBuildError if CasADi cannot generate C for the functions, or if
    the generated code keeps mutable static state (which would break several
    instances running side by side); ConfigError for an unknown profile or precision.
    """
    check_options(profile, precision)
    names = {"NNFMU_INIT": f"{prefix}_entry_init", "NNFMU_STEP": f"{prefix}_entry_step"}
    single = precision == "float32"
    functions = {entry: _renamed(fn, entry) for entry, fn in zip(names.values(), (model.init, model.step))}
    options = {"with_header": True, "verbose": False, "prefix": prefix, "casadi_real": "float" if single else "double"}
    generator = ca.CodeGenerator(MODEL_C, options)
    try:
        for entry, fn in functions.items():
            generator.add(_renamed(fn, single_precision.inner_name(entry)) if single else fn)
        generator.generate(str(directory) + "/")
    except RuntimeError as exc:
        raise FmuBuildError(
            f"CasADi cannot generate C code for model {model.spec.name!r}: {exc}; build init and step "
            f"from code-generatable operations (no external or plugin functions)") from exc
    path = Path(directory) / MODEL_C
    source = patch_source(path.read_text(encoding="utf-8"), speed_patch=speed_patch, profile=profile,
                          precision=precision)
    mutable = _MUTABLE_STATIC.findall(source)
    if mutable:
        raise FmuBuildError(
            f"the generated C for {model.spec.name!r} keeps mutable static state ({mutable[0].strip()!r}), "
            f"so FMU instances would share it; use CasADi functions without memory objects")
    if single:
        source = _insert_before_epilogue(source, single_precision.adapters(functions))
        (Path(directory) / MODEL_H).write_text(single_precision.header(list(functions)), encoding="utf-8")
    path.write_text(source, encoding="utf-8")
    entry = dict(names)
    entry.update({f"{macro}_WORK": f"{symbol}_work" for macro, symbol in names.items()})
    return GeneratedCode(MODEL_C, MODEL_H, entry, model.n_x)


def _insert_before_epilogue(source: str, text: str) -> str:
    cut = source.rindex(_EPILOGUE)
    return source[:cut] + text + source[cut:]
