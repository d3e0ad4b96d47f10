"""CasADi Functions compiled to C and called from torch, with CasADi's compiled reverse mode as the gradient.

The fast torch path for a physics model written once in CasADi.
:func:`sx_to_torch` runs one torch operation per SX instruction (a few
microseconds each); this module instead generates C for the Function and for
its reverse-mode derivative ``fn.reverse(1)``, adds a small batch loop, and
compiles them once into a shared library (cached by :mod:`nnfmu.cbuild`, like
:func:`nnfmu.physics.compile_function`). A call hands the tensors' memory to
that loop through :mod:`ctypes`: one C call per batch, forward and backward::

    ode_t = compiled_to_torch(valve_system().ode)
    (xdot,) = ode_t(x, u, p)        # x (B, n_x), u (B, n_u), p (n_p,) -> xdot (B, n_x)
    xdot.pow(2).sum().backward()    # adjoints by the compiled reverse(1), summed over the batch for p

:func:`casadi_to_torch` picks this backend (``"compiled"``) or the
translation of :func:`sx_to_torch` (``"sx"``) behind one option; both take
and return the same shapes. The C code computes in float64: inputs are cast to
float64 and the outputs back to the inputs' dtype. Gradients are first order
(CasADi's reverse mode, so NaN in an untaken ``if_else`` branch does not leak);
a second derivative raises an error.
"""

from __future__ import annotations

import ctypes
import os
import tempfile
import warnings
from pathlib import Path

import casadi as ca
import torch
from torch.autograd.function import once_differentiable

from nnfmu import cbuild
from nnfmu.errors import ConfigError, ExportError, FmuBuildError, ShapeError, SimulationError
from nnfmu.hybrid.casadi_torch import _common_dtype, sx_to_torch

BACKENDS = ("compiled", "sx")

# The batch loop: calls the generated function once per sample; an input with stride 0 is shared by all.
_DRIVER = r"""
/* ---- nnfmu: batch loop over the generated function (nnfmu/hybrid/compiled_torch.py) ---- */
#include <stdlib.h>
static int nnfmu_loop(int (*f)(const casadi_real**, casadi_real**, casadi_int*, casadi_real*, int),
                      int n_in, int n_out, casadi_int sz_arg, casadi_int sz_res, casadi_int sz_iw,
                      casadi_int sz_w, long long n, const double** in, const long long* in_stride,
                      double** out, const long long* out_stride) {
  const casadi_real** arg = malloc((sz_arg + 1) * sizeof(*arg));
  casadi_real** res = malloc((sz_res + 1) * sizeof(*res));
  casadi_int* iw = malloc((sz_iw + 1) * sizeof(*iw));
  casadi_real* w = malloc((sz_w + 1) * sizeof(*w));
  int status = (arg && res && iw && w) ? 0 : -1;
  for (long long k = 0; k < n && status == 0; ++k) {
    for (int i = 0; i < n_in; ++i) arg[i] = in[i] + k * in_stride[i];
    for (int j = 0; j < n_out; ++j) res[j] = out[j] + k * out_stride[j];
    if (f(arg, res, iw, w, 0)) status = 1;
  }
  free(arg); free(res); free(iw); free(w);
  return status;
}
"""
_ENTRY = r"""
__attribute__((visibility("default")))
int nnfmu_{kind}(long long n, const double** in, const long long* in_stride, double** out,
                 const long long* out_stride) {{
  return nnfmu_loop({name}, {n_in}, {n_out}, {sz_arg}, {sz_res}, {sz_iw}, {sz_w}, n, in, in_stride, out, out_stride);
}}
"""


def casadi_to_torch(fn: ca.Function, *, backend: str = "compiled"):
    """A torch callable evaluating ``fn`` on batches, with gradients: compiled C or the SX translation.

    Parameters
    ----------
    fn : casadi.Function
        Dense column-vector inputs. ``"sx"`` needs an SX Function (or one that expands to SX);
        ``"compiled"`` takes any code-generable Function (SX, or MX without cvodes/idas).
    backend : {"compiled", "sx"}
        ``"compiled"``: :class:`CompiledFunction` (fast; needs a C compiler: without one, or if
        compiling fails, a RuntimeWarning says so and the SX translation is used).
        ``"sx"``: :func:`sx_to_torch` (no compiler; one torch operation per SX instruction).

    Returns
    -------
    callable ``f(*inputs) -> tuple of tensors``; inputs ``(..., numel_i)`` broadcast over their
    leading shapes, outputs ``(*batch, numel_j)``.
    """
    if backend not in BACKENDS:
        raise ConfigError(f"unknown physics backend {backend!r}; choose one of {', '.join(BACKENDS)}")
    if backend == "sx":
        return sx_to_torch(fn)
    try:
        return CompiledFunction(fn)
    except FmuBuildError as exc:  # as nnfmu.physics.compile_function does: slower, same numbers
        warnings.warn(f"{fn.name()} runs as the SX translation instead of compiled C (slower, same values): "
                      f"{str(exc).splitlines()[0]}", RuntimeWarning, stacklevel=2)
        return sx_to_torch(fn)


def compiled_to_torch(fn: ca.Function, *, compiler: str | None = None) -> "CompiledFunction":
    """``fn`` compiled to C (with its reverse mode) as a torch callable; see the module docstring."""
    return CompiledFunction(fn, compiler=compiler)


def _dense_function(fn: ca.Function) -> ca.Function:
    """``fn`` with every output densified (the C code then writes plain column-major arrays)."""
    if not isinstance(fn, ca.Function):
        raise ExportError(f"expected a casadi.Function, got {type(fn).__name__}")
    for i in range(fn.n_in()):
        if not fn.sparsity_in(i).is_dense():
            raise ExportError(f"input {fn.name_in(i)!r} of {fn.name()!r} is sparse; compiled_to_torch needs dense "
                              "inputs (build them with SX.sym(name, n))")
    if fn.has_free():
        raise ExportError(f"Function {fn.name()!r} has free variables {fn.get_free()}; make them inputs")
    symbols = fn.sx_in() if fn.is_a("SXFunction") else fn.mx_in()
    outputs = [ca.densify(o) for o in fn.call(symbols)]
    return ca.Function(fn.name(), symbols, outputs, fn.name_in(), fn.name_out())


def _reverse_function(fn: ca.Function) -> ca.Function:
    """Dense ``reverse(1)``: (inputs, nominal outputs, output seeds) -> adjoints of every input."""
    rev = fn.reverse(1)
    symbols = rev.sx_in() if rev.is_a("SXFunction") else rev.mx_in()
    outputs = [ca.densify(o) for o in rev.call(symbols)]
    return ca.Function(f"adj_{fn.name()}", symbols, outputs, rev.name_in(), rev.name_out())


def _source(fwd: ca.Function, rev: ca.Function) -> str:
    with tempfile.TemporaryDirectory(prefix="nnfmu_bridge_") as tmp:
        gen = ca.CodeGenerator("bridge.c", {"with_header": False})
        gen.add(fwd)
        gen.add(rev)
        gen.generate(tmp + os.sep)
        code = (Path(tmp) / "bridge.c").read_text()
    entries = "".join(
        _ENTRY.format(kind=kind, name=f.name(), n_in=f.n_in(), n_out=f.n_out(), sz_arg=f.sz_arg(),
                      sz_res=f.sz_res(), sz_iw=f.sz_iw(), sz_w=f.sz_w())
        for kind, f in (("forward", fwd), ("reverse", rev)))
    # Empty CASADI_SYMBOL_EXPORT + hidden visibility: the generated symbols stay private to this library.
    return "#define CASADI_SYMBOL_EXPORT\n" + code + _DRIVER + entries


#: Characters of generated C above which it is compiled at -O1: GCC's -O2/-O3 time grows faster than linearly
#: with the size of one straight-line function. A hybrid's fused step on a user's two-tank model (1.9 MB of C,
#: hidden 32) took 153 CPU-s at -O3 and 18 s at -O1, and trained at the same speed (3.5 against 4.1 CPU-s for
#: 3 epochs, AMD EPYC); the slider_viscous one (3.6 MB) had not compiled after 5 CPU-minutes at -O3.
LARGE_SOURCE = 1_000_000


def _flags(source: str) -> tuple[str, ...]:
    """The build flags: :data:`nnfmu.cbuild.DEFAULT_FLAGS`, with -O1 for sources over :data:`LARGE_SOURCE`."""
    if len(source) <= LARGE_SOURCE:
        return tuple(cbuild.DEFAULT_FLAGS)
    return tuple("-O1" if flag.startswith("-O") else flag for flag in cbuild.DEFAULT_FLAGS)


def _library(source: str, name: str, compiler: str | None) -> ctypes.CDLL:
    """Compile ``source`` once (cached by its hash, :func:`nnfmu.cbuild.build_cached`) and load it."""
    target = cbuild.build_cached(f"torch_{name}", source, flags=(*_flags(source), "-shared"), compiler=compiler,
                                 what=f"compiling {name!r} for torch (physics backend 'compiled'; "
                                      "use 'sx' where no C compiler is available)")
    lib = cbuild.load(target)
    for entry in (lib.nnfmu_forward, lib.nnfmu_reverse):
        entry.restype = ctypes.c_int
        entry.argtypes = [ctypes.c_longlong, ctypes.c_void_p, ctypes.c_void_p, ctypes.c_void_p, ctypes.c_void_p]
    return lib


def _pointers(tensors) -> ctypes.Array:
    return (ctypes.c_void_p * max(len(tensors), 1))(*(t.data_ptr() for t in tensors))


def _strides(values) -> ctypes.Array:
    return (ctypes.c_longlong * max(len(values), 1))(*values)


class CompiledFunction:
    """A CasADi Function as compiled C, callable on torch tensors (build it with :func:`compiled_to_torch`).

    ``cf(*inputs)`` or ``cf(name=value, ...)`` returns one tensor per output port. Input ``i``
    has shape ``(..., numel_i)``; the leading shapes broadcast against each other (a parameter
    vector ``(n_p,)`` can meet states ``(B, n_x)``: it is passed once, not copied per sample, and
    its gradient is summed over the batch). Outputs have shape ``(*batch, numel_j)`` and the
    widest floating dtype of the tensor inputs; the C code runs in float64.

    Attributes
    ----------
    name : str
    name_in, name_out : tuple of str
    numel_in, numel_out : tuple of int
    """

    def __init__(self, fn: ca.Function, *, compiler: str | None = None):
        self.function = _dense_function(fn)
        self.reverse_function = _reverse_function(self.function)
        self.name = self.function.name()
        self.name_in, self.name_out = tuple(self.function.name_in()), tuple(self.function.name_out())
        self.numel_in = tuple(self.function.numel_in(i) for i in range(self.function.n_in()))
        self.numel_out = tuple(self.function.numel_out(i) for i in range(self.function.n_out()))
        self._lib = _library(_source(self.function, self.reverse_function), self.name, compiler)

    def __deepcopy__(self, memo) -> "CompiledFunction":
        return self  # immutable: the compiled library and its Functions are shared by copies of a model

    def __repr__(self) -> str:
        ports_in = ", ".join(f"{n}[{k}]" for n, k in zip(self.name_in, self.numel_in))
        ports_out = ", ".join(f"{n}[{k}]" for n, k in zip(self.name_out, self.numel_out))
        return f"CompiledFunction({self.name}: ({ports_in}) -> ({ports_out}))"

    def __call__(self, *args, **kwargs) -> tuple[torch.Tensor, ...]:
        values = self._bind(args, kwargs)
        dtype = _common_dtype(values)
        tensors = [v if isinstance(v, torch.Tensor) else torch.as_tensor(v, dtype=torch.float64) for v in values]
        batch = self._batch_shape(tensors)
        if torch.is_grad_enabled() and any(t.requires_grad for t in tensors):
            outputs = _CompiledCall.apply(self, batch, *tensors)
        else:  # nothing to differentiate: skip the autograd node
            outputs = self.evaluate(batch, tensors)[0]
        return tuple(o if o.dtype == dtype else o.to(dtype) for o in outputs)

    def evaluate(self, batch: torch.Size, tensors) -> tuple[tuple[torch.Tensor, ...], list, list]:
        """Outputs ``(*batch, numel_j)`` float64, plus the flat inputs and outputs the reverse pass needs."""
        flat = [_flat(t, batch) for t in tensors]
        outputs = self.forward_batch(batch.numel(), [f for f, _ in flat], [s for _, s in flat])
        return tuple(o.reshape(*batch, o.shape[-1]) for o in outputs), flat, outputs

    def _batch_shape(self, tensors: list) -> torch.Size:
        """The common leading shape, as torch broadcasting defines it; checks the last dimensions and the device."""
        for t, name, numel in zip(tensors, self.name_in, self.numel_in):
            if t.dim() == 0 or t.shape[-1] != numel:
                raise ShapeError(f"{self.name}: input {name!r} has shape {tuple(t.shape)}, expected (..., {numel}); "
                                 f"put the {numel} entries in the last dimension")
            if t.device.type != "cpu":
                raise ShapeError(f"{self.name}: input {name!r} is on {t.device}; the compiled physics runs on the CPU")
        leads = {t.shape[:-1] for t in tensors if t.dim() > 1}
        if len(leads) <= 1:  # the common case, cheaply: one batch shape, and vectors shared by all its rows
            return leads.pop() if leads else torch.Size()
        try:
            return torch.broadcast_shapes(*(t.shape[:-1] for t in tensors))
        except RuntimeError:
            shapes = {n: tuple(t.shape) for n, t in zip(self.name_in, tensors)}
            raise ShapeError(f"{self.name}: the batch shapes of the inputs {shapes} do not broadcast") from None

    def _bind(self, args: tuple, kwargs: dict) -> list:
        if kwargs:
            if args or set(kwargs) != set(self.name_in):
                raise ShapeError(f"{self.name}: pass the inputs {list(self.name_in)} either all by position or all "
                                 f"by name, got {len(args)} positional and {sorted(kwargs)}")
            return [kwargs[n] for n in self.name_in]
        if len(args) != len(self.name_in):
            raise ShapeError(f"{self.name}: expected {len(self.name_in)} inputs {list(self.name_in)}, got {len(args)}")
        return list(args)

    # ---- the two C entry points -------------------------------------------------------------
    def _run(self, entry, n: int, inputs: list, strides: list, numels: tuple) -> list[torch.Tensor]:
        outputs = [torch.empty((n, k), dtype=torch.float64) for k in numels]
        status = entry(n, _pointers(inputs), _strides(strides), _pointers(outputs), _strides(numels))
        if status != 0:
            raise SimulationError(f"the compiled {self.name} failed (status {status}) on a batch of {n}")
        return outputs

    def forward_batch(self, n: int, inputs: list, strides: list) -> list[torch.Tensor]:
        """Outputs ``(n, numel_j)`` float64 of contiguous float64 inputs (stride 0: shared by all samples)."""
        return self._run(self._lib.nnfmu_forward, n, inputs, strides, self.numel_out)

    def reverse_batch(self, n: int, inputs: list, strides: list, outputs: list, seeds: list) -> list[torch.Tensor]:
        """Per-sample adjoints ``(n, numel_i)`` of every input, given the nominal outputs and their seeds."""
        extra = [k for k in self.numel_out] * 2
        return self._run(self._lib.nnfmu_reverse, n, inputs + outputs + seeds, strides + extra, self.numel_in)


def _flat(t: torch.Tensor, batch: torch.Size) -> tuple[torch.Tensor, int]:
    """Contiguous float64 ``(B, numel)`` (or ``(1, numel)`` with stride 0 when ``t`` has no batch entries)."""
    numel = t.shape[-1]
    t = t.to(torch.float64)
    if t.shape[:-1].numel() == 1:
        return t.reshape(1, numel).contiguous(), 0
    if t.shape[:-1] != batch:
        t = t.expand(*batch, numel)
    return t.reshape(-1, numel).contiguous(), numel


class _CompiledCall(torch.autograd.Function):
    """Forward: the compiled Function. Backward: the compiled ``reverse(1)``, reduced to each input's shape."""

    @staticmethod
    def forward(ctx, cf: CompiledFunction, batch: torch.Size, *inputs: torch.Tensor):
        result, flat, outputs = cf.evaluate(batch, inputs)
        ctx.cf, ctx.batch, ctx.flat, ctx.outputs = cf, batch, flat, outputs
        ctx.shapes = [t.shape for t in inputs]
        return result

    @staticmethod
    @once_differentiable
    def backward(ctx, *seeds: torch.Tensor):
        needed = ctx.needs_input_grad[2:]
        if not any(needed):
            return (None,) * (2 + len(needed))
        n, batch = ctx.batch.numel(), ctx.batch
        seeds = [s.detach().to(torch.float64).reshape(n, -1).contiguous() for s in seeds]
        adjoints = ctx.cf.reverse_batch(n, [f for f, _ in ctx.flat], [s for _, s in ctx.flat], ctx.outputs, seeds)
        grads = []
        for adj, shape, keep in zip(adjoints, ctx.shapes, needed):
            grads.append(adj.reshape(*batch, adj.shape[-1]).sum_to_size(shape) if keep else None)
        return (None, None, *grads)
