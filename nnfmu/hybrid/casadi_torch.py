"""CasADi SX Functions evaluated as torch operations, so that gradients flow through a physics model.

A physics ODE is written once, in CasADi SX. :func:`sx_to_torch` translates the
Function's instruction list into the source of one Python function of torch
operations, compiles it once, and wraps it in a :class:`TorchFunction`
module::

    ode = valve_system().ode                 # casadi Function ode(x, u, p) -> xdot
    ode_t = sx_to_torch(ode)
    (xdot,) = ode_t(x, u, p)                 # x (B, n_x), u (B, n_u), p (n_p,) -> xdot (B, n_x)
    xdot.pow(2).sum().backward()             # gradients reach x, u and p

Gradients (``gradients=``):

- ``"casadi"`` (default): a custom autograd node whose backward pass evaluates
  CasADi's own reverse-mode derivative ``fn.reverse(1)``, translated the same
  way. Gradients are CasADi's to rounding, also at kinks (``fmin`` ties split
  evenly, ``fabs'(0) = 0``) and across ``if_else``: a NaN or inf in the branch
  that is not taken does not leak into the gradient, as it does in plain torch
  autograd. Only inputs and outputs are kept for the backward pass, so memory
  does not grow with the size of the graph. Higher derivatives use
  ``reverse(1)`` of the reverse Function, and so on.
- ``"autograd"``: plain torch autograd through the translated operations.
  Needed for ``torch.func`` transforms; records every intermediate.

On a CUDA device (``"casadi"`` mode) the translated code runs through :func:`torch.compile`, which
fuses its hundreds of element-wise operations into a few kernels: one launch instead of one per
instruction, compiled once per function, dtype and batch shape. Where compiling fails (no Triton,
an old GPU) it warns once and runs the operations one by one (same numbers, slower).
``NNFMU_COMPILED_ROLLOUT=0`` turns it off.
"""

from __future__ import annotations

import os
import warnings

import casadi as ca
import numpy as np
import torch

from nnfmu.errors import ConfigError, ExportError, ShapeError
from nnfmu.hybrid._sx_source import GeneratedSource, generate_source
from nnfmu.training.compiled_rollout import ENV_SWITCH

GRADIENT_MODES = ("casadi", "autograd")
FUSED_DEVICES = ("cuda",)  #: device types whose translated code runs through torch.compile (module docstring)


def sx_to_torch(fn: ca.Function, *, gradients: str = "casadi") -> "TorchFunction":
    """Translate a CasADi Function into a torch module evaluating it on batches of tensors.

    Parameters
    ----------
    fn : casadi.Function
        An SX Function, or an MX Function that ``fn.expand()`` turns into one, with no
        free variables.
    gradients : {"casadi", "autograd"}
        How gradients are computed; see the module docstring.

    Returns
    -------
    TorchFunction
        ``tf(*inputs) -> tuple of outputs``; each input has shape ``(B, numel_i)`` or
        ``(numel_i,)``, each output ``(B, numel_j)`` (dense, column-major for matrices).

    Raises
    ------
    ExportError
        If ``fn`` has free variables, cannot be expanded to SX, or uses an operation with
        no torch translation (the message names it).
    ConfigError
        If ``gradients`` is not one of ``"casadi"``, ``"autograd"``.
    """
    return TorchFunction(fn, gradients=gradients)


def _as_sx_function(fn: ca.Function) -> ca.Function:
    if not isinstance(fn, ca.Function):
        raise ExportError(f"expected a casadi.Function, got {type(fn).__name__}; build one with casadi.Function(...)")
    if not fn.is_a("SXFunction"):
        try:
            fn = fn.expand()
        except RuntimeError as error:
            raise ExportError(
                f"Function {fn.name()!r} is a {fn.class_name()} that cannot be expanded to SX "
                f"({str(error).strip().splitlines()[-1]}); build the model with casadi.SX symbols"
            ) from None
    if fn.has_free():
        raise ExportError(
            f"Function {fn.name()!r} has free variables {fn.get_free()}; make them inputs of the Function"
        )
    return fn


class TorchFunction(torch.nn.Module):
    """A CasADi SX Function evaluated with torch operations (build it with :func:`sx_to_torch`).

    Calling it as ``tf(*inputs)`` or ``tf(name=value, ...)`` (CasADi's port names) returns
    a tuple with one tensor per output port.

    Shapes: input ``i`` is ``(..., numel_i)``, a CasADi matrix port flattened column-major;
    the leading (batch) shapes of the inputs broadcast against each other, so a parameter
    vector ``(n_p,)`` can meet states ``(B, n_x)``. Each output is ``(*batch, numel_j)``.
    All inputs are cast to one floating dtype (the widest floating tensor input's; float64
    if only NumPy arrays or Python numbers are given) and must share a device; outputs
    have that dtype and device.

    Cost: one torch operation per SX instruction, each a few microseconds on a CPU almost
    independently of the batch size, so batch generously; the backward pass of the
    "casadi" mode evaluates ``reverse(1)``, about 2.5 times as many instructions.

    Attributes
    ----------
    name : str
        The CasADi Function's name.
    name_in, name_out : tuple of str
        Port names.
    numel_in, numel_out : tuple of int
        Number of entries per port (the size of the last tensor dimension).
    gradients : str
        ``"casadi"`` or ``"autograd"``.
    n_instructions : int
        Number of SX instructions translated.
    """

    def __init__(self, fn: ca.Function, *, gradients: str = "casadi"):
        super().__init__()
        if gradients not in GRADIENT_MODES:
            raise ConfigError(
                f"gradients={gradients!r} is not a gradient mode; valid modes are: {', '.join(GRADIENT_MODES)}"
            )
        fn = _as_sx_function(fn)
        self.function = fn
        self.name = fn.name()
        self.name_in, self.name_out = tuple(fn.name_in()), tuple(fn.name_out())
        self.numel_in = tuple(fn.numel_in(i) for i in range(fn.n_in()))
        self.numel_out = tuple(fn.numel_out(i) for i in range(fn.n_out()))
        self.gradients = gradients
        self.n_instructions = fn.n_instructions()
        # Under "casadi" the forward pass never records autograd, so fmin/fmax can keep C's NaN rule.
        self._generated = generate_source(fn, nan_ignoring_minmax=gradients == "casadi")
        self._compiled = _compile(self._generated, fn.name())
        self._constants: dict[tuple[torch.dtype, torch.device], tuple[torch.Tensor, ...]] = {}
        self._reverse: dict[tuple[bool, ...], TorchFunction] = {}
        self._fused = None  # torch.compile of _compiled, made at the first call on a CUDA device
        self._fusing_failed = False

    def __getstate__(self) -> dict:
        # The compiled code and the caches are rebuilt on unpickling; the CasADi Function pickles itself.
        state = self.__dict__.copy()
        state.update(_compiled=None, _constants={}, _reverse={}, _fused=None, _fusing_failed=False)
        return state

    def __setstate__(self, state: dict) -> None:
        super().__setstate__(state)
        self._compiled = _compile(self._generated, self.name)

    @property
    def source(self) -> str:
        """The generated Python source (for reading and debugging)."""
        return self._generated.source

    def extra_repr(self) -> str:
        ports_in = ", ".join(f"{n}[{k}]" for n, k in zip(self.name_in, self.numel_in))
        ports_out = ", ".join(f"{n}[{k}]" for n, k in zip(self.name_out, self.numel_out))
        return (f"{self.name}: ({ports_in}) -> ({ports_out}), {self.n_instructions} instructions, "
                f"gradients={self.gradients!r}")

    def forward(self, *args, **kwargs) -> tuple[torch.Tensor, ...]:
        inputs = _broadcast_inputs(self, self._bind(args, kwargs))
        if self.gradients == "casadi":
            return _CasadiGradient.apply(self, *inputs)
        return self.evaluate(inputs)

    def evaluate(self, inputs: tuple[torch.Tensor, ...]) -> tuple[torch.Tensor, ...]:
        """Run the generated code on checked inputs of one dtype, device and batch shape (no custom gradient)."""
        first = inputs[0] if inputs else torch.empty(0)
        key = (first.dtype, first.device)
        if key not in self._constants:
            values = torch.tensor(self._generated.constants, dtype=torch.float64)
            self._constants[key] = tuple(values.to(dtype=key[0], device=key[1]).unbind())
        batch = first.shape[:-1] if inputs else torch.Size()
        if self._fuses(key[1]):
            try:
                return self._fused(self._constants[key], key[0], key[1], *inputs)
            except Exception as exc:  # noqa: BLE001 (torch.compile's failures have no common type)
                self._fusing_failed = True
                warnings.warn(f"{self.name}: torch.compile cannot fuse the translated operations on {key[1]} "
                              f"({type(exc).__name__}: {str(exc).strip().splitlines()[0] if str(exc).strip() else ''}); "
                              "they run one by one (same numbers, slower)", RuntimeWarning, stacklevel=2)
        return self._compiled(self._constants[key], key[0], key[1], batch, *inputs)

    def _fuses(self, device: torch.device) -> bool:
        """Whether to run the code through torch.compile: "casadi" gradients on a CUDA device (module docstring)."""
        if (device.type not in FUSED_DEVICES or self.gradients != "casadi" or self._fusing_failed
                or not self.numel_in or os.environ.get(ENV_SWITCH, "1") == "0"):
            return False
        if self._fused is None:
            # One compilation for every batch size (dynamic shapes), of a function object of its own: torch.compile
            # caches by code object, and all translated functions sharing one would exhaust its recompile limit.
            self._fused = torch.compile(_compile(_batch_from_input(self._generated), self.name), fullgraph=True,
                                        dynamic=True)
        return True

    def reverse(self, needed: tuple[bool, ...]) -> "TorchFunction":
        """The translated ``reverse(1)`` Function, keeping only the adjoints of inputs marked in ``needed``.

        Its inputs are this Function's inputs, its nominal outputs and the output seeds;
        its outputs are the adjoints ``adj_<input>`` of the needed inputs.
        """
        if needed not in self._reverse:
            full = self.function.reverse(1)
            symbols = full.sx_in()
            kept = [i for i, keep in enumerate(needed) if keep]
            adjoints = full.call(symbols)
            pruned = ca.Function(
                f"adj_{self.name}", symbols, [adjoints[i] for i in kept],
                full.name_in(), [full.name_out(i) for i in kept],
            )
            self._reverse[needed] = TorchFunction(pruned, gradients=self.gradients)
        return self._reverse[needed]

    def _bind(self, args: tuple, kwargs: dict) -> list:
        if kwargs:
            unknown = sorted(set(kwargs) - set(self.name_in))
            if unknown or args:
                raise ShapeError(
                    f"{self.name}: pass the inputs {list(self.name_in)} either all by position or all by name"
                    + (f"; unknown names {unknown}" if unknown else "")
                )
            missing = [n for n in self.name_in if n not in kwargs]
            if missing:
                raise ShapeError(f"{self.name}: missing input(s) {missing}; expected {list(self.name_in)}")
            return [kwargs[n] for n in self.name_in]
        if len(args) != len(self.name_in):
            raise ShapeError(f"{self.name}: expected {len(self.name_in)} inputs {list(self.name_in)}, got {len(args)}")
        return list(args)


def _batch_from_input(generated: GeneratedSource) -> GeneratedSource:
    """The same function with the batch shape read from its first input, ``(c, dt, dev, a0, ...)``.

    The batch shape as an argument would be a Python value that torch.compile specialises on; read from a
    tensor it stays symbolic, so one compilation serves the training batch, the last one and validation.
    """
    header, body = generated.source.split("\n", 1)
    prefix = f"def {generated.function_name}(c, dt, dev, batch, a0"
    if not header.startswith(prefix):
        raise ExportError(f"unexpected generated header {header!r}")  # a change of _sx_source's layout
    header = header.replace(", batch, a0", ", a0", 1)
    return GeneratedSource(f"{header}\n    batch = a0.shape[:-1]\n{body}", generated.function_name,
                           generated.constants)


def _compile(generated: GeneratedSource, name: str):
    namespace = {"torch": torch}
    exec(compile(generated.source, f"<sx_to_torch {name}>", "exec"), namespace)  # noqa: S102 (our own source)
    return namespace[generated.function_name]


def _common_dtype(values: list) -> torch.dtype:
    """The widest floating dtype of the tensor inputs; float64 if there are none but there are NumPy/Python values."""
    floating = [v.dtype for v in values if isinstance(v, torch.Tensor) and v.is_floating_point()]
    if not floating:
        return torch.float64 if any(not isinstance(v, torch.Tensor) for v in values) else torch.get_default_dtype()
    dtype = floating[0]
    for other in floating[1:]:
        dtype = torch.promote_types(dtype, other)
    return dtype


def _broadcast_inputs(tf: TorchFunction, values: list) -> tuple[torch.Tensor, ...]:
    """Check the last dimensions, then cast to one dtype and expand to one batch shape (views, no copies)."""
    dtype = _common_dtype(values)
    # NumPy arrays and Python numbers go through float64, so that no digit is lost before the cast.
    tensors = [v if isinstance(v, torch.Tensor) else torch.as_tensor(np.asarray(v, dtype=np.float64)) for v in values]
    devices = {t.device for t in tensors}
    if len(devices) > 1:
        raise ShapeError(f"{tf.name}: inputs are on several devices {sorted(map(str, devices))}; move them to one")
    for t, name, numel in zip(tensors, tf.name_in, tf.numel_in):
        if t.dim() == 0 or t.shape[-1] != numel:
            raise ShapeError(
                f"{tf.name}: input {name!r} has shape {tuple(t.shape)}, expected (..., {numel}) "
                f"(batch, {numel} entries); put the {numel} entries in the last dimension"
            )
    try:
        batch = torch.broadcast_shapes(*(t.shape[:-1] for t in tensors))
    except RuntimeError:
        shapes = {n: tuple(t.shape) for n, t in zip(tf.name_in, tensors)}
        raise ShapeError(
            f"{tf.name}: the batch shapes of the inputs {shapes} do not broadcast; give them one batch size"
        ) from None
    return tuple(t.to(dtype).expand(*batch, t.shape[-1]) for t in tensors)


class _CasadiGradient(torch.autograd.Function):
    """Forward: the translated Function. Backward: the translated ``reverse(1)`` Function."""

    @staticmethod
    def forward(ctx, tf: TorchFunction, *inputs: torch.Tensor):
        outputs = tf.evaluate(inputs)
        ctx.tf = tf
        ctx.save_for_backward(*inputs, *outputs)
        return outputs

    @staticmethod
    def backward(ctx, *seeds: torch.Tensor):
        needed = tuple(ctx.needs_input_grad[1:])
        if not any(needed):
            return (None,) * len(ctx.needs_input_grad)
        adjoints = iter(ctx.tf.reverse(needed)(*ctx.saved_tensors, *seeds))
        return (None, *(next(adjoints) if keep else None for keep in needed))
