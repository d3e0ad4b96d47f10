"""What one FMU step costs: the weights its matrix products read, their bytes and FLOPs (``nnfmu info``).

A network's step reads each weight of its matrix products once, and the products are nearly all of its
arithmetic, so ``weight_bytes`` sets the step's floor on a given cache (docs/fmu-speed.md: "the weight-read
bound") and ``flops`` (2 per weight and column multiplied) its work. Element-wise operations (the gates'
exp and tanh, the linear path's scalar products) are not counted. The same figures come from a step
Function (:func:`function_cost`, for a checkpoint) and from the C an FMU ships (:func:`source_cost`).
"""

from __future__ import annotations

import re
from dataclasses import dataclass

import casadi as ca

from nnfmu.errors import FmuBuildError
from nnfmu.export.codegen import CALL, MODEL_BODY, STEP_ENTRY


@dataclass(frozen=True)
class StepCost:
    """Per step: ``weights`` read by the matrix products, their ``flops``, and ``real_bytes`` per weight."""

    weights: int
    flops: int
    real_bytes: int = 8

    @property
    def weight_bytes(self) -> int:
        return self.weights * self.real_bytes

    def as_dict(self) -> dict:
        return {"weights": self.weights, "weight_bytes": self.weight_bytes, "flops": self.flops,
                "precision": "float32" if self.real_bytes == 4 else "float64"}


def function_cost(step: ca.Function, real_bytes: int = 8) -> StepCost:
    """The cost of an MX ``step``: every ``mtimes`` of a constant matrix and a column block in its graph."""
    weights = flops = 0
    if not step.is_a("MXFunction"):
        return StepCost(0, 0, real_bytes)  # scalar SX code (physics): no matrix products
    for k in range(step.n_instructions()):
        if step.instruction_id(k) == ca.OP_CALL:  # a Function called in the step (a hybrid's network, per stage)
            inner = function_cost(step.instruction_MX(k).which_function(), real_bytes)
            weights, flops = weights + inner.weights, flops + inner.flops
        if step.instruction_id(k) != ca.OP_MTIMES:
            continue
        _, a, b = (step.instruction_MX(k).dep(i) for i in range(3))  # z + a @ b
        matrix, other = (a, b) if a.is_constant() else (b, a)
        weights += matrix.nnz()
        flops += 2 * matrix.nnz() * (other.size2() if matrix is a else other.size1())
    return StepCost(weights, flops, real_bytes)


_PRODUCT = re.compile(r"\b(?:nnfmu_gemv_panel|casadi_mtimes_dense)\(\s*[^,]+,\s*(\d+),\s*(\d+),\s*[^,]+,\s*(\d+)")
_REAL = re.compile(r"^#define casadi_real (float|double)\s*$", re.M)


def source_cost(source: str) -> StepCost:
    """The cost of the step in an FMU's ``sources/model_casadi.c`` (written by :mod:`nnfmu.export.codegen`).

    Counts the products of the step's C function and of the model functions it calls, each call (a hybrid's
    network: once per RK4 stage), as :func:`function_cost` does. Raises FmuBuildError
    for C that nnfmu did not generate.
    """
    step, real = STEP_ENTRY.search(source), _REAL.search(source)
    if step is None or real is None:
        raise FmuBuildError("the FMU's sources/model_casadi.c has no nnfmu step entry point; only FMUs built by "
                            "nnfmu show their step cost")
    bodies = dict(MODEL_BODY.findall(source))

    def cost(name: str) -> tuple[int, int]:
        products = [(int(r) * int(c), 2 * int(r) * int(c) * int(n)) for r, c, n in _PRODUCT.findall(bodies[name])]
        products += [cost(callee) for callee in CALL.findall(bodies[name]) if callee in bodies]
        return sum(w for w, _ in products), sum(f for _, f in products)

    weights, flops = cost(step.group(1))
    return StepCost(weights, flops, 4 if real.group(1) == "float" else 8)
