"""A hybrid's whole step, every RK4 stage with its correction network, as one compiled call.

:meth:`HybridStepModel._advance` computes a step as ``4 n_sub`` compiled ODE calls (one
per RK4 stage) with the correction network run in torch in every stage: about ten torch
operations and autograd nodes per stage, whose fixed cost dominated hybrid training (10-14
ms per step forward and backward on the valve; docs/scaling.md). This module writes the
whole step as one CasADi Function whose inputs include the network's weights::

    step(x, u, un, p, w) -> (x_next, y_next)
        w: every Linear of the correction, weight (row-major) then bias, in module order

with the same operations as the torch model (the network on ``[x / state_scale, un]``, the
correction scattered onto the corrected states, RK4 over ``ode + delta`` or the physics'
RK4 plus ``Ts * delta``), and compiles it with its reverse mode through
:mod:`nnfmu.hybrid.compiled_torch`: one C call per step forward, one backward, gradients for
``x``, ``p`` and ``w`` by CasADi's reverse mode. The step is expanded to SX: straight-line C
forward and reverse (an MX fold over the sub-steps compiled smaller, but its reverse mode was
slower than the per-stage path: 13.8 against 12.4 ms per valve step). Unrolled, the arm's
50 sub-steps of a 4208-instruction ODE would take minutes to compile, so where ``4 n_sub`` ODE
evaluations exceed :data:`MAX_ODE_INSTRUCTIONS` the step is a C loop over one sub-step expanded to
SX (an MX fold; 12 s to compile for the arm). Its cost is per trajectory: on one trajectory (the
arm's validation run) it is 19 times faster than the per-stage path, whose fixed cost per stage
spreads over a batch; with gradients on more than :data:`LOOPED_MAX_BATCH` trajectories the
per-stage path runs.

It applies (besides that size) to the ``compiled`` physics backend on the CPU without active
dropout; the C code computes in float64 (as the physics always does). ``NNFMU_COMPILED_ROLLOUT=0`` turns it off,
as it does the compiled recurrent free run. Values and gradients equal the per-stage
path to rounding (tests/test_hybrid_fused.py, float64, 1e-12).
"""

from __future__ import annotations

import os
import warnings

import casadi as ca
import torch
from torch import nn

from nnfmu.errors import FmuBuildError
from nnfmu.export.casadi_layers import ACTIVATIONS, activation_expr
from nnfmu.hybrid.compiled_torch import CompiledFunction
from nnfmu.physics import rk4_step
from nnfmu.physics.rk4 import physics_step, rk4_function
from nnfmu.training.compiled_rollout import ENV_SWITCH


def fused_step(model, batch: int) -> CompiledFunction | None:
    """The compiled whole step of ``model`` (a HybridStepModel) for ``batch`` trajectories, or None where the
    per-stage path must run (or is faster: the looped step with gradients on large batches)."""
    config = model.config
    if os.environ.get(ENV_SWITCH, "1") == "0":
        return None
    if config.physics_backend != "compiled" or model.u_mean.device.type != "cpu":
        return None
    if model.training and config.dropout > 0:  # torch draws the dropout masks
        return None
    modules = _modules(model)
    if any(not isinstance(m, (nn.Linear, *ACTIVATIONS)) for m in modules):
        return None
    if not unrolled(model) and torch.is_grad_enabled() and batch > LOOPED_MAX_BATCH:
        return None
    key = structure_key(model)
    if key not in _COMPILED:  # one compiled step per layout: the model supplies the structure, not the weights
        _COMPILED[key] = _compile(model)
    return _COMPILED[key]


def structure_key(model) -> tuple:
    """What :func:`step_function`'s graph depends on besides the weights and the physical parameters (a cache key)."""
    config = model.config
    return (config.physics_key(), config.correction, model.Ts, model.n_sub, config.n_u, _layout(_modules(model)),
            tuple(model._state_scale.tolist()), tuple(model._scatter.reshape(-1).tolist()))


def weight_vector(model) -> torch.Tensor:
    """``w``: the correction's Linear weights (row-major) and biases, flattened in module order (1-D)."""
    parts = []
    for m in _modules(model):
        if isinstance(m, nn.Linear):
            parts += [m.weight.reshape(-1), m.bias]
    return torch.cat(parts)


def _modules(model) -> list[nn.Module]:
    """The correction's modules that compute something (inactive dropout left out)."""
    return [m for m in model.correction if not isinstance(m, nn.Dropout)]


def _layout(modules) -> tuple:
    return tuple((type(m).__name__, *(m.weight.shape if isinstance(m, nn.Linear) else ())) for m in modules)


_COMPILED: dict[tuple, CompiledFunction | None] = {}
MAX_ODE_INSTRUCTIONS = 50_000  # ODE instructions in one unrolled step (the valve: 253 x 16)
#: Trajectories up to which the looped step also trains (forward and backward). Its cost is per trajectory, and the
#: per-stage path's fixed cost per stage spreads over the batch: on the arm (hidden 32, one thread, AMD EPYC) the
#: looped step made 95-129 trajectory-steps/s at any batch, the per-stage path 7 at batch 1, 43 at 8, 78 at 16 and
#: 153 at 32 (benchmarks/hybrid_speed.py --physics arm). Without gradients (validation, scoring) it always runs.
LOOPED_MAX_BATCH = 16


def _compile(model) -> CompiledFunction | None:
    try:
        return CompiledFunction(step_function(model))
    except FmuBuildError as exc:
        warnings.warn(f"the hybrid step runs stage by stage instead of as one compiled call (slower, same values): "
                      f"{str(exc).splitlines()[0]}", RuntimeWarning, stacklevel=3)
        return None


def unrolled(model) -> bool:
    """Whether the fused step is one straight-line SX graph (else a C loop over one SX sub-step; module docstring)."""
    return 4 * model.n_sub * model.physics.ode.n_instructions() <= MAX_ODE_INSTRUCTIONS


def step_function(model) -> ca.Function:
    """``step(x, u, un, p, w) -> (x_next, y_next)`` of ``model`` as a CasADi Function (see the module docstring)."""
    system, config, n_x = model.physics, model.config, model.n_x
    flat = unrolled(model)
    modules = _modules(model)
    n_w = sum(m.weight.numel() + m.bias.numel() for m in modules if isinstance(m, nn.Linear))
    x, u = ca.MX.sym("x", n_x), ca.MX.sym("u", config.n_u)
    un, p, w = ca.MX.sym("un", config.n_u), ca.MX.sym("p", len(system.parameters)), ca.MX.sym("w", n_w)
    first = modules[0]
    w1, b1 = _linear_weights(w, 0, first)
    input_term = ca.mtimes(w1[:, n_x:], un) + b1  # constant over the step's RK4 stages, as in the torch model
    delta = _delta_function(model, modules, n_w)
    if config.correction == "step":
        rk4 = (physics_step(system, model.Ts, model.n_sub) if flat  # else a C loop over one SX sub-step
               else rk4_function(system.ode, Ts=model.Ts, n_sub=model.n_sub, unroll_max=0, name=f"{system.name}_rk4"))
        x_next = rk4(x, u, p) + model.Ts * delta(x, input_term, w)
    else:  # n_sub RK4 sub-steps of ode + delta, as a C loop over one sub-step (fold), not n_sub copies
        h = model.Ts / model.n_sub
        c = ca.MX.sym("c", first.out_features)
        sub = ca.Function("substep", [x, u, p, c, w],
                          [rk4_step(lambda x_, u_, p_: system.ode(x_, u_, p_) + delta(x_, c, w), x, u, p, Ts=h)])
        x_next = (sub if flat else sub.expand()).fold(model.n_sub)(x, u, p, input_term, w)
    y_next = system.output(x_next, p)
    step = ca.Function(f"{system.name}_hybrid_step", [x, u, un, p, w], [x_next, y_next],
                       ["x", "u", "un", "p", "w"], ["x_next", "y_next"])
    # Unrolled: SX, whose reverse mode is straight-line C (the MX fold's reverse was slower than per stage on the
    # valve). Too large to unroll: the MX loop over one SX sub-step, which compiles in seconds.
    return step.expand() if flat else step


def _linear_weights(w, at: int, layer: nn.Linear):
    """``(W, b)`` of ``layer`` from the flat vector ``w`` starting at ``at`` (row-major W)."""
    n_out, n_in = layer.weight.shape
    W = ca.reshape(w[at:at + n_out * n_in], n_in, n_out).T
    return W, w[at + n_out * n_in:at + n_out * n_in + n_out]


def _delta_function(model, modules, n_w: int) -> ca.Function:
    """``delta(x, c, w)``: the correction of the state derivative, with ``c = W1_u un + b1``, as SX."""
    n_x = model.n_x
    x, c, w = ca.SX.sym("x", n_x), ca.SX.sym("c", modules[0].out_features), ca.SX.sym("w", n_w)
    scale = ca.DM(model._state_scale.tolist())
    w1, _ = _linear_weights(w, 0, modules[0])
    v = ca.mtimes(w1[:, :n_x], x / scale) + c
    at = modules[0].weight.numel() + modules[0].bias.numel()
    for i, module in enumerate(modules[1:], start=1):
        if isinstance(module, nn.Linear):
            W, b = _linear_weights(w, at, module)
            v = ca.mtimes(W, v) + b
            at += module.weight.numel() + module.bias.numel()
        else:
            v = activation_expr(module, v, f"correction.{i}")
    scatter = ca.DM(model._scatter.detach().to(torch.float64).numpy())
    return ca.Function("delta", [x, c, w], [ca.mtimes(scatter, v)], ["x", "c", "w"], ["xdot_correction"])
