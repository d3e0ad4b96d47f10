"""Turn the instruction list of a CasADi SX Function into the Python source of one torch function.

The source is generated once per Function and compiled with :func:`compile`, so
evaluating it runs one torch operation per SX instruction with no interpreter
loop over the instructions. The generated function is::

    def <name>(c, dt, dev, batch, a0, a1, ...):  # -> tuple of output tensors
        ...

with ``c`` the tuple of the Function's constants as 0-dim tensors of dtype
``dt`` on device ``dev``, ``batch`` the common leading shape and ``a<i>`` the
input tensors, each of shape ``batch + (numel_i,)`` (dense, column-major).

Values keep the kind CasADi gives them implicitly: comparisons and logical
operations yield torch ``bool`` tensors (CasADi's 0.0/1.0), converted to the
float dtype only where arithmetic or an output needs a number. That saves a
cast on every ``if_else`` condition.
"""

from __future__ import annotations

from dataclasses import dataclass

import casadi as ca

from nnfmu.errors import ExportError

OP_NAMES = {getattr(ca, n): n for n in dir(ca) if n.startswith("OP_")}

_UNARY_FUNCTIONS = {
    "OP_EXP": "torch.exp", "OP_LOG": "torch.log", "OP_SQRT": "torch.sqrt", "OP_SQ": "torch.square",
    "OP_INV": "torch.reciprocal", "OP_SIN": "torch.sin", "OP_COS": "torch.cos", "OP_TAN": "torch.tan",
    "OP_ASIN": "torch.asin", "OP_ACOS": "torch.acos", "OP_ATAN": "torch.atan", "OP_SINH": "torch.sinh",
    "OP_COSH": "torch.cosh", "OP_TANH": "torch.tanh", "OP_ASINH": "torch.asinh", "OP_ACOSH": "torch.acosh",
    "OP_ATANH": "torch.atanh", "OP_ERF": "torch.erf", "OP_LOG1P": "torch.log1p",
    "OP_EXPM1": "torch.expm1", "OP_FLOOR": "torch.floor", "OP_CEIL": "torch.ceil", "OP_FABS": "torch.abs",
    "OP_SIGN": "torch.sign",
}
_BINARY_FUNCTIONS = {
    "OP_POW": "torch.pow", "OP_ATAN2": "torch.atan2", "OP_FMOD": "torch.fmod",
    "OP_COPYSIGN": "torch.copysign", "OP_HYPOT": "torch.hypot",
}
_BINARY_OPERATORS = {"OP_ADD": "+", "OP_SUB": "-", "OP_MUL": "*", "OP_DIV": "/"}
_COMPARISONS = {"OP_LT": "<", "OP_LE": "<=", "OP_EQ": "==", "OP_NE": "!="}
_LOGICAL = {"OP_AND": "&", "OP_OR": "|"}

# Why some operations CasADi's SX can hold are refused, for the error message.
_UNSUPPORTED_REASONS = {
    "OP_ERFINV": "CasADi's own erfinv is an approximation (errors up to 1e-7 below -0.7) that torch cannot "
                 "reproduce to 1e-12, and its generated C calls an erfinv() that the C library lacks",
    "OP_REMAINDER": "C's remainder() has no exact torch counterpart; use fmod",
    "OP_CALL": "the Function calls another Function (one built with 'never_inline'); build it inlined",
}

SUPPORTED_OPS = frozenset(
    set(_UNARY_FUNCTIONS) | set(_BINARY_FUNCTIONS) | set(_BINARY_OPERATORS) | set(_COMPARISONS)
    | set(_LOGICAL)
    | {"OP_PRINTME", "OP_NEG", "OP_TWICE", "OP_CONSTPOW", "OP_NOT", "OP_IF_ELSE_ZERO", "OP_FMIN", "OP_FMAX",
       "OP_CONST", "OP_INPUT", "OP_OUTPUT"}
)
"""Names of the CasADi operation codes the translator handles (``casadi.OP_<NAME>``)."""


@dataclass(frozen=True)
class GeneratedSource:
    """Python source of a translated Function and the constants it indexes as ``c[k]``."""

    source: str
    function_name: str
    constants: tuple[float, ...]


class _Emitter:
    """Walks the instructions once, tracking for each work slot its kind and whether it varies with the inputs."""

    def __init__(self, fn: ca.Function, *, nan_ignoring_minmax: bool):
        self.fn = fn
        self.minmax = ("torch.fmin", "torch.fmax") if nan_ignoring_minmax else ("torch.minimum", "torch.maximum")
        self.lines: list[str] = []
        self.kind: dict[int, str] = {}  # work slot -> "f" (float tensor) or "b" (bool tensor)
        self.varying: dict[int, bool] = {}  # work slot -> depends on an input (else: a 0-dim constant)
        self.constants: dict[str, int] = {}  # float.hex() (tells -0.0 from 0.0) -> index into c
        self.constant_values: list[float] = []  # index into c -> value
        self.outputs: dict[tuple[int, int], str] = {}  # (port, nonzero) -> variable
        self.input_positions: dict[int, list[int]] = {}  # port -> dense position of each nonzero

    def constant_index(self, value: float) -> int:
        """Index of ``value`` in ``c``; constants with equal bits share one entry."""
        index = self.constants.setdefault(value.hex(), len(self.constants))
        if index == len(self.constant_values):
            self.constant_values.append(value)
        return index

    def as_float(self, w: int) -> str:
        return f"w{w}.to(dt)" if self.kind[w] == "b" else f"w{w}"

    def as_bool(self, w: int) -> str:
        return f"w{w}" if self.kind[w] == "b" else f"(w{w} != 0)"

    def assign(self, w: int, expression: str, kind: str, varying: bool) -> None:
        self.lines.append(f"    w{w} = {expression}")
        self.kind[w], self.varying[w] = kind, varying

    def instruction(self, k: int) -> None:
        op = OP_NAMES.get(self.fn.instruction_id(k), f"operation {self.fn.instruction_id(k)}")
        args, res = self.fn.instruction_input(k), self.fn.instruction_output(k)
        if op == "OP_INPUT":
            port, nz = args
            if port not in self.input_positions:
                self.input_positions[port] = self.fn.sparsity_in(port).find()
            self.assign(res[0], f"i{port}[{self.input_positions[port][nz]}]", "f", True)
        elif op == "OP_OUTPUT":
            self.output(args[0], *res)
        elif op == "OP_CONST":
            index = self.constant_index(float(self.fn.instruction_constant(k)))
            self.assign(res[0], f"c[{index}]", "f", False)
        else:
            expression, kind = self.operation(op, args)
            self.assign(res[0], expression, kind, any(self.varying[a] for a in args))

    def operation(self, op: str, args: list[int]) -> tuple[str, str]:
        f = [self.as_float(a) for a in args]
        if op in _UNARY_FUNCTIONS:
            return f"{_UNARY_FUNCTIONS[op]}({f[0]})", "f"
        if op in _BINARY_OPERATORS:
            return f"{f[0]} {_BINARY_OPERATORS[op]} {f[1]}", "f"
        if op in _BINARY_FUNCTIONS:
            return f"{_BINARY_FUNCTIONS[op]}({f[0]}, {f[1]})", "f"
        if op in _COMPARISONS:
            return f"{f[0]} {_COMPARISONS[op]} {f[1]}", "b"
        if op in _LOGICAL:
            return f"{self.as_bool(args[0])} {_LOGICAL[op]} {self.as_bool(args[1])}", "b"
        if op == "OP_PRINTME":  # printme(x, y) returns x; its print at evaluation time is dropped
            return f"w{args[0]}", self.kind[args[0]]
        if op == "OP_NEG":
            return f"-{f[0]}", "f"
        if op == "OP_TWICE":
            return f"{f[0]} + {f[0]}", "f"
        if op == "OP_CONSTPOW":  # the exponent is a constant: no derivative flows to it
            return f"torch.pow({f[0]}, {f[1]})", "f"
        if op == "OP_NOT":
            return f"~{self.as_bool(args[0])}", "b"
        if op == "OP_IF_ELSE_ZERO":
            # A 0-dim zero tensor is faster here than the Python scalar 0.0 (no wrapping per call).
            return f"torch.where({self.as_bool(args[0])}, {f[1]}, c[{self.constant_index(0.0)}])", "f"
        if op in ("OP_FMIN", "OP_FMAX"):
            return f"{self.minmax[op == 'OP_FMAX']}({f[0]}, {f[1]})", "f"
        reason = _UNSUPPORTED_REASONS.get(op, "it has no torch translation")
        raise ExportError(
            f"cannot translate CasADi operation {op} of Function {self.fn.name()!r} into torch: {reason}; "
            f"rewrite the model with the supported operations {', '.join(sorted(SUPPORTED_OPS))}"
        )

    def output(self, w: int, port: int, nz: int) -> None:
        name = f"o{port}_{nz}"
        value = self.as_float(w)
        # A constant output element is a 0-dim tensor: give it the batch shape so that it stacks.
        self.lines.append(f"    {name} = {value}" if self.varying[w] else f"    {name} = {value}.expand(batch)")
        self.outputs[(port, nz)] = name

    def assemble_outputs(self) -> list[str]:
        lines, results = [], []
        if any(self.fn.nnz_out(i) < self.fn.numel_out(i) for i in range(self.fn.n_out())):
            lines.append("    zero = torch.zeros(batch, dtype=dt, device=dev)")
        for port in range(self.fn.n_out()):
            elements = ["zero"] * self.fn.numel_out(port)
            for nz, position in enumerate(self.fn.sparsity_out(port).find()):
                elements[position] = self.outputs.get((port, nz), "zero")
            if elements:
                lines.append(f"    r{port} = torch.stack([{', '.join(elements)}], -1)")
            else:
                lines.append(f"    r{port} = torch.zeros(batch + (0,), dtype=dt, device=dev)")
            results.append(f"r{port}")
        lines.append(f"    return ({''.join(r + ', ' for r in results)})")
        return lines


def generate_source(fn: ca.Function, *, nan_ignoring_minmax: bool) -> GeneratedSource:
    """Translate an SX Function (no free variables) into the source of one Python function.

    Parameters
    ----------
    fn : casadi.Function
        An ``SXFunction``.
    nan_ignoring_minmax : bool
        Translate ``fmin``/``fmax`` to ``torch.fmin``/``torch.fmax``, which ignore a NaN argument
        as C does; otherwise to ``torch.minimum``/``torch.maximum``, whose autograd derivative
        splits a tie evenly as CasADi's does, but which propagate NaN.

    Raises
    ------
    ExportError
        For an operation that has no torch translation.
    """
    emitter = _Emitter(fn, nan_ignoring_minmax=nan_ignoring_minmax)
    for k in range(fn.n_instructions()):
        emitter.instruction(k)
    unbind = [f"    i{port} = a{port}.unbind(-1)" for port in sorted(emitter.input_positions)]
    body = unbind + emitter.lines + emitter.assemble_outputs()
    function_name = f"sx_{fn.name()}"  # a prefix, so that a Function called 'torch' cannot shadow the module
    arguments = ", ".join(["c", "dt", "dev", "batch"] + [f"a{i}" for i in range(fn.n_in())])
    header = f"def {function_name}({arguments}):"
    return GeneratedSource("\n".join([header, *body]) + "\n", function_name, tuple(emitter.constant_values))
