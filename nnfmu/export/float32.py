"""``precision="float32"``: the model computes in single precision behind the FMU's float64 interface.

CasADi generates ``model_casadi.c`` with ``casadi_real`` = ``float`` under
inner names (``<prefix>_f32_init``, ``<prefix>_f32_step``); :func:`adapters`
appends the entry points the FMU wrapper calls, which take and return
``double`` and convert at the boundary: the state ``x`` and the inputs are
rounded to float on the way in (``x`` was float already, so it round-trips
exactly), the results widened on the way out. :func:`header` replaces
CasADi's header with their float64 declarations. The wrapper templates do
not change.
"""

from __future__ import annotations

import casadi as ca

_ADAPTER = """
/* nnfmu float32 adapter: the FMU's interface stays double; the model computes in float (casadi_real). */
int {entry}(const double** arg, double** res, casadi_int* iw, double* w, int mem) {{
  static const casadi_int nnz_in[{n_in}] = {{{nnz_in}}}, nnz_out[{n_out}] = {{{nnz_out}}};
  const casadi_real* a[{sz_arg}];
  casadi_real* r[{sz_res}];
  casadi_real *f = (casadi_real*)w, *out;
  casadi_int i, j;
  int flag;
  for (i = 0; i < {sz_arg}; ++i) a[i] = 0;
  for (i = 0; i < {sz_res}; ++i) r[i] = 0;
  for (i = 0; i < {n_in}; f += nnz_in[i], ++i) {{
    if (!arg[i]) continue;
    for (j = 0; j < nnz_in[i]; ++j) f[j] = (casadi_real)arg[i][j];
    a[i] = f;
  }}
  out = f;
  for (i = 0; i < {n_out}; f += nnz_out[i], ++i) if (res[i]) r[i] = f;
  flag = {inner}(a, r, iw, f, mem);
  for (i = 0, f = out; i < {n_out}; f += nnz_out[i], ++i) {{
    if (!res[i]) continue;
    for (j = 0; j < nnz_out[i]; ++j) res[i][j] = (double)f[j];
  }}
  return flag;
}}

int {entry}_work(casadi_int *sz_arg, casadi_int* sz_res, casadi_int *sz_iw, casadi_int *sz_w) {{
  casadi_int floats = 0;
  {inner}_work(sz_arg, sz_res, sz_iw, &floats);
  if (sz_arg) *sz_arg = {sz_arg};
  if (sz_res) *sz_res = {sz_res};
  if (sz_w) *sz_w = (floats + {io}) / 2 + 1; /* doubles that hold the float work and the converted I/O */
  return 0;
}}
"""

_HEADER = """/* nnfmu float32 build: the model computes in single precision (model_casadi.c); these entry points
   take and return double, converting at the boundary. */
#ifndef casadi_real
#define casadi_real double
#endif
#ifndef casadi_int
#define casadi_int long long int
#endif
#ifdef __cplusplus
extern "C" {{
#endif
{declarations}
#ifdef __cplusplus
}} /* extern "C" */
#endif
"""


def inner_name(entry: str) -> str:
    """The single-precision function behind ``entry`` (``<prefix>_entry_step`` -> ``<prefix>_f32_step``)."""
    return entry.replace("_entry_", "_f32_")


def adapters(functions: dict[str, ca.Function]) -> str:
    """C of the float64 entry points around the float functions; ``functions`` maps entry name -> Function."""
    parts = []
    for entry, fn in functions.items():
        nnz_in = [fn.nnz_in(i) for i in range(fn.n_in())]
        nnz_out = [fn.nnz_out(i) for i in range(fn.n_out())]
        parts.append(_ADAPTER.format(
            entry=entry, inner=inner_name(entry), n_in=fn.n_in(), n_out=fn.n_out(),
            nnz_in=", ".join(map(str, nnz_in)), nnz_out=", ".join(map(str, nnz_out)),
            sz_arg=max(fn.sz_arg(), fn.n_in()), sz_res=max(fn.sz_res(), fn.n_out()),
            io=sum(nnz_in) + sum(nnz_out)))
    return "".join(parts)


def header(entries: list[str]) -> str:
    """``model_casadi.h`` for the float32 build: the float64 entry points and their work-size queries."""
    declarations = []
    for entry in entries:
        declarations += [
            f"int {entry}(const casadi_real** arg, casadi_real** res, casadi_int* iw, casadi_real* w, int mem);",
            f"int {entry}_work(casadi_int *sz_arg, casadi_int* sz_res, casadi_int *sz_iw, casadi_int *sz_w);"]
    return _HEADER.format(declarations="\n".join(declarations))
