"""The ss network's state loop as compiled C (``state_loop.c``), forward and backward.

:meth:`nnfmu.ss.model.SSStepModel._states` runs the loop ``z_{k+1} = A z_k + B u_k + b + s f(z_k, u_k)`` over a
window's steps. In torch each step is about ten small operations and as many autograd nodes, whose fixed cost, not
the arithmetic, bounds a training's optimiser steps per second (the robot's windows: 43 x 207 steps, forward and
backward 43 ms in torch). ``state_loop.c`` runs the loop in one call and back-propagation through it in another, with
the same operations; torch keeps what is outside the loop (the input's shares of the first layer and of the linear
model, the encoder's initial state, the output map ``h``), so its autograd reaches every weight::

    loop = compiled_states(model)       # None where the C loop does not apply
    zs = loop(z0, drive, pre)           # (B, n_x), (B, T, n_x), (B, T, hidden) -> (B, T, n_x): z_1 .. z_T

It applies on the CPU in float32 or float64, to a model of exactly :class:`~nnfmu.ss.model.SSStepModel` (a subclass
may compute another step; the model checks that) with at least one hidden layer. The library is compiled at first
use and cached like the other compiled free runs (:mod:`nnfmu.training.rollout_library`); without a compiler it warns
once and torch runs the loop (slower, same values). ``NNFMU_COMPILED_ROLLOUT=0`` turns it off. Values and gradients
equal torch's to rounding (tested in float64).
"""

from __future__ import annotations

import ctypes
import functools
import os
from pathlib import Path

import torch

from nnfmu.training.compiled_rollout import ENV_SWITCH
from nnfmu.training.compiled_window import ACTIVATIONS
from nnfmu.training.rollout_library import REALS, check, compiled, or_none, pointers, ptr

_C_FILE = Path(__file__).with_name("state_loop.c")


@functools.lru_cache(maxsize=None)
def _library(dtype: torch.dtype) -> ctypes.CDLL | None:
    lib = or_none(lambda: compiled(dtype, _C_FILE), "the ss network's state loop")
    if lib is None:
        return None
    header = [ctypes.c_int] * 6 + [ctypes.c_double]
    lib.nnfmu_ss_forward.argtypes = header + [ctypes.c_void_p] * 8
    lib.nnfmu_ss_backward.argtypes = header + [ctypes.c_void_p] * 11
    lib.nnfmu_ss_forward.restype = lib.nnfmu_ss_backward.restype = ctypes.c_int
    return lib


def compiled_states(model):
    """``loop(z0, drive, pre) -> zs`` by the compiled state loop (module docstring), or None where it does not apply.

    ``model``: an :class:`~nnfmu.ss.model.SSStepModel`, not a subclass (the model checks it: a subclass may compute
    another step)."""
    c = model.config
    if os.environ.get(ENV_SWITCH, "1") == "0" or c.layers < 1:
        return None
    tensors = [*model.f.parameters(), model.lin_A]
    dtype = tensors[0].dtype
    if dtype not in REALS or any(t.device.type != "cpu" or t.dtype != dtype for t in tensors):
        return None
    if c.activation not in ACTIVATIONS:
        return None
    library = _library(dtype)
    if library is None:
        return None
    return functools.partial(_apply, model, library)


def _weights(model) -> list[torch.Tensor]:
    """``W_z, W_1, b_1, ..., W_o, b_o`` (``state_loop.c``'s ``params``); ``W_z``: the first layer's state columns."""
    linears = [m for m in model.f if isinstance(m, torch.nn.Linear)]
    s = model.config.n_states
    rest = [t for layer in linears[1:] for t in (layer.weight, layer.bias)]
    return [linears[0].weight[:, :s], *rest]


def _apply(model, library: ctypes.CDLL, z0: torch.Tensor, drive: torch.Tensor, pre: torch.Tensor) -> torch.Tensor:
    return _StateLoop.apply(model, library, z0, drive, pre, *_weights(model))


def _header(model, B: int, T: int) -> tuple:
    c = model.config
    return (B, T, c.n_states, c.hidden, c.layers, ACTIVATIONS[c.activation], float(model.scale))


class _StateLoop(torch.autograd.Function):
    """Forward: ``nnfmu_ss_forward``. Backward: ``nnfmu_ss_backward``. Time-major inside."""

    @staticmethod
    def forward(ctx, model, library, z0, drive, pre, *weights):
        B, T, s = drive.shape
        dtype = weights[0].dtype
        z0_c = z0.detach().to(dtype).contiguous()
        drive_t = drive.detach().to(dtype).transpose(0, 1).contiguous()
        pre_t = pre.detach().to(dtype).transpose(0, 1).contiguous()
        flat = [w.detach().contiguous() for w in weights]
        A = model.lin_A.detach().contiguous()
        zs_t = drive_t.new_empty(T, B, s)
        keep = any(ctx.needs_input_grad[2:])
        c = model.config
        hs = drive_t.new_empty(T, c.layers, B, c.hidden) if keep else None
        args = drive_t.new_empty(hs.shape) if keep and c.activation == "silu" else None
        status = library.nnfmu_ss_forward(*_header(model, B, T), ptr(A), pointers(flat), ptr(z0_c), ptr(drive_t),
                                          ptr(pre_t), ptr(zs_t), ptr(hs), ptr(args))
        check(status, "ss state loop", B, T)
        if keep:
            ctx.model, ctx.library = model, library
            ctx.save_for_backward(A, z0_c, zs_t, hs, args, *flat)
        return zs_t.transpose(0, 1).to(drive.dtype)

    @staticmethod
    def backward(ctx, gzs):
        A, z0_c, zs_t, hs, args, *flat = ctx.saved_tensors
        T, B, s = zs_t.shape
        grads = [torch.zeros_like(w) for w in flat]
        gzs_t = gzs.to(zs_t.dtype).transpose(0, 1).contiguous()
        gz0, gdrive = torch.empty_like(z0_c), torch.empty_like(zs_t)
        gpre = zs_t.new_empty(T, B, ctx.model.config.hidden)
        status = ctx.library.nnfmu_ss_backward(*_header(ctx.model, B, T), ptr(A), pointers(flat), ptr(z0_c),
                                               ptr(zs_t), ptr(hs), ptr(args), ptr(gzs_t), pointers(grads), ptr(gz0),
                                               ptr(gdrive), ptr(gpre))
        check(status, "back-propagation through the ss state loop", B, T)
        need = ctx.needs_input_grad
        return (None, None, gz0 if need[2] else None, gdrive.transpose(0, 1) if need[3] else None,
                gpre.transpose(0, 1) if need[4] else None, *(g if n else None for g, n in zip(grads, need[5:])))
