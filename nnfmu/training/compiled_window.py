"""The window networks' free run (TCN, MLP) as compiled C (``window_rollout.c``), for ``compiled_rollout``.

Same contract as the recurrent networks' (``rollout(un, yn0) -> ys``, back-propagated by torch's autograd): a
:class:`~nnfmu.networks.tcn.model.TCNStepModel` or :class:`~nnfmu.networks.mlp.model.MLPStepModel` (a network
whose record's cell is one of ``window_rollout.c``, :mod:`nnfmu.training.rollout_cells`), or a
:class:`~nnfmu.models.linear_path.LinearPathStepModel` on one, in eval mode or with no active dropout, with or
without feedback noise (drawn as torch's loop draws it), without an init window or increment mode (the conditions
:func:`nnfmu.training.compiled_rollout.compiled_rollout` checks). In torch a step of the TCN is a few dozen small
operations, 2 ms forward and backward at batch 9 on one thread, and the MLP's about 0.9 ms: the slowest free runs
of the five networks (docs/accuracy.md). Values and gradients equal torch's to rounding (tested in float64).
"""

from __future__ import annotations

import ctypes

import torch

from nnfmu.models.base import StepModel
from nnfmu.training.rollout_cells import compiled_cell
from nnfmu.training.rollout_library import backward_buffers, check, feedback_noise, path_arguments, pointers, ptr, run

ACTIVATIONS = {"tanh": 0, "relu": 1, "sigmoid": 2, "elu": 3, "silu": 4}  # window_rollout.c's codes


def apply(model: StepModel, library: ctypes.CDLL, un: torch.Tensor, yn0: torch.Tensor) -> torch.Tensor:
    """The free run of ``model`` (a TCN or MLP, or a linear path on one): (B, T, n_u), (B, n_y) -> (B, T, n_y),
    normalised."""
    return run(_WindowRollout, model, library, un, yn0, _weights)


def _weights(model: StepModel) -> list[torch.Tensor]:
    """Per layer its weight and bias, then the output layer's, in window_rollout.c's order."""
    return list(compiled_cell(model).weights)


def _header(model: StepModel, B: int, T: int) -> tuple:
    c, cell = model.config, compiled_cell(model)
    return (cell.code, B, T, c.n_u, c.n_y, c.hidden, c.layers, cell.taps, ACTIVATIONS[c.activation], int(c.skip),
            float(c.skip_scale))


class _WindowRollout(torch.autograd.Function):
    """Forward: ``nnfmu_window_forward``. Backward: ``nnfmu_window_backward``. Time-major inside.

    ``model``: the TCN or MLP; with a linear path, ``fixed`` = its ``[A, B, b, C, d]``, ``z0`` (B, n_z) its initial
    state, and ``weights`` end with ``G``, ``alpha``; else ``fixed`` and ``z0`` are None. ``noise_std``: the std of
    the feedback noise (0: none), drawn here as the torch loop draws it (one ``randn_like`` of (B, n_y) a step, in
    order).
    """

    @staticmethod
    def forward(ctx, model, fixed, library, noise_std, un, yn0, z0, *weights):
        B, T, _ = un.shape
        c, dtype = model.config, weights[0].dtype
        weights = [w.detach().contiguous() for w in weights]
        un_t = un.detach().to(dtype).transpose(0, 1).contiguous()
        yn0 = yn0.detach().to(dtype).contiguous()
        z0 = None if z0 is None else z0.detach().to(dtype).contiguous()
        noise = feedback_noise(noise_std, yn0, T)
        fed = None if noise is None else torch.empty_like(noise)
        ys_t = un_t.new_empty(T, B, c.n_y)
        keep = any(ctx.needs_input_grad[4:])
        shape = (max(T - 1, 0), c.layers, B, c.hidden)
        hs = un_t.new_empty(shape) if keep else None
        kept = un_t.new_empty(shape) if keep else None
        rest, rest_kept = un_t.new_empty(c.layers, B, c.hidden), un_t.new_empty(c.layers, B, c.hidden)
        ns = un_t.new_empty(max(T - 1, 0), B, c.n_y) if keep and fixed is not None else None
        status = library.nnfmu_window_forward(*_header(model, B, T), pointers(weights), ptr(un_t), ptr(yn0),
                                              ptr(noise), ptr(ys_t), ptr(fed), ptr(hs), ptr(kept), ptr(rest),
                                              ptr(rest_kept), *path_arguments(fixed), ptr(z0), ptr(ns))
        check(status, "free run", B, T)
        if keep:
            ctx.model, ctx.library, ctx.fixed = model, library, fixed
            ctx.save_for_backward(un_t, ys_t, fed, hs, kept, rest, rest_kept, ns, *weights)
        return ys_t.transpose(0, 1).to(un.dtype)

    @staticmethod
    def backward(ctx, gys):
        un_t, ys_t, fed, hs, kept, rest, rest_kept, ns, *weights = ctx.saved_tensors
        T, B, _ = un_t.shape
        grads, gys_t, gyn0, gz0 = backward_buffers(weights, gys, ctx.fixed)
        status = ctx.library.nnfmu_window_backward(*_header(ctx.model, B, T), pointers(weights), ptr(un_t),
                                                   ptr(ys_t), ptr(fed), ptr(hs), ptr(kept), ptr(rest),
                                                   ptr(rest_kept), ptr(gys_t), pointers(grads), ptr(gyn0),
                                                   *path_arguments(ctx.fixed), ptr(ns), ptr(gz0))
        check(status, "back-propagation through the free run", B, T)
        needed = ctx.needs_input_grad
        return (None, None, None, None, None, gyn0 if needed[5] else None, gz0 if needed[6] else None,
                *(g if need else None for g, need in zip(grads, needed[7:])))
