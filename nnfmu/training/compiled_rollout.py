"""The free run of the recurrent networks (RNN, LSTM, GRU), the TCN and the MLP as compiled C, forward and backward.

Parallel training back-propagates through hundreds of steps of a small network. In
torch each step is 15-20 small operations (a TCN's, a few dozen) and as many autograd nodes; at the batch
sizes used here their fixed cost of a few microseconds each, not arithmetic, bounds
the throughput (docs/scaling.md has the measurements). ``rollout.c`` runs the whole
free run of a recurrent network in one call and back-propagation through time in another, with the same
operations as :meth:`~nnfmu.networks.recurrent.model.RecurrentStepModel.free_run_norm`; ``window_rollout.c``
(:mod:`nnfmu.training.compiled_window`) does the same for the window networks' step (the TCN's dilated layers
over their delay lines, the MLP's layers over its window)::

    rollout = compiled_rollout(model)        # None where the C path does not apply
    ys = rollout(un, yn0)                    # (B, T, n_u), (B, n_y) -> (B, T, n_y), as model.rollout_normalised
    loss(ys).backward()                      # gradients of every weight (and of yn0)

It applies to a model whose architecture's record names the compiled cell that computes its step
(``Architecture.rollout_cell``, a :class:`~nnfmu.training.rollout_cells.CompiledCell` of ``rollout.c`` or
``window_rollout.c``, e.g. :mod:`nnfmu.networks.recurrent.rollout`) and that is exactly the record's model class
(the layout the cell describes), and to a
:class:`~nnfmu.models.linear_path.LinearPathStepModel` whose network is one (the path's linear
state runs in C too; its initial state ``z0`` is computed by torch and back-propagated through), on
the CPU in float32 or float64, with no active dropout (eval mode, or zero), no init window and no increment mode.
Feedback noise in training is drawn by torch as its own loop draws it and added in C, so the numbers are the
same. The library is compiled at first use with the system C compiler (``-O3 -march=native``, glibc's vector ``exp``/``tanh``) and cached
like the compiled physics (``$NNFMU_CACHE_DIR``; :mod:`nnfmu.training.rollout_library`). Without a compiler, or if
compiling fails, :func:`compiled_rollout` warns once and returns None: torch runs the free run
(slower, same numbers). ``NNFMU_COMPILED_ROLLOUT=0`` turns the C path off.
Values and gradients equal torch's to rounding (tested in float64 to 1e-12, with and without a linear path).
"""

from __future__ import annotations

import ctypes
import functools
import os

import torch

from nnfmu.models import architectures
from nnfmu.models.base import StepModel
from nnfmu.models.linear_path import LinearPathStepModel
from nnfmu.training import compiled_window, rollout_cells
from nnfmu.training.rollout_library import (FIXED, REALS, backward_buffers, check, feedback_noise,
                                            library_or_none, path_arguments, pointers, ptr, run)

ENV_SWITCH = "NNFMU_COMPILED_ROLLOUT"


def compiled_rollout(model: StepModel):
    """``rollout(un, yn0) -> ys`` by the compiled free run, or None where it does not apply.

    Applies to a model whose record names a ``rollout_cell`` (module docstring), or a
    :class:`LinearPathStepModel` on one, whose weights
    (and buffers of the path) are CPU float32/float64 tensors, without an init window or increment mode,
    and whose dropout is inactive (eval mode, or zero); None otherwise, and None with a one-time RuntimeWarning
    when the library cannot be compiled.
    """
    if not _applies(model):
        return None
    net = model.net if type(model) is LinearPathStepModel else model
    cell = rollout_cells.compiled_cell(net)
    library = library_or_none(model.u_mean.dtype, cell.library)
    if library is None:
        return None
    if cell.library == rollout_cells.WINDOW:
        return functools.partial(compiled_window.apply, model, library)
    return functools.partial(_apply, model, library)


def training_rollout(model: StepModel):
    """``free_run(un, yn, past=None) -> predictions (B, T, n_y)``: a parallel training batch's free run from ``yn[:, 0]``.

    The compiled free run where it applies (:func:`compiled_rollout`; never with an init window
    ``past``), or the architecture's own (``Architecture.training_rollout``, e.g. the hybrid's CUDA graphs)
    where it gives one, else ``model.rollout_normalised(un, yn[:, 0], None, past)``. Call it after
    ``model.train()`` and after setting ``model.feedback_noise``: both decide what it computes.
    """
    own = architectures.architecture(model.config.arch).get("training_rollout")
    if own is not None and (free_run := own(model)) is not None:
        return free_run
    fast = compiled_rollout(model)
    if fast is None:
        return lambda un, yn, past=None: model.rollout_normalised(un, yn[:, 0], None, past)
    return lambda un, yn, past=None: fast(un, yn[:, 0])


def free_run_forward(model: StepModel, u: torch.Tensor, y0: torch.Tensor) -> torch.Tensor:
    """``model(u, y0)``: the free run in physical units, (B, T, n_u), (B, n_y) -> (B, T, n_y); compiled where it can."""
    fast = compiled_rollout(model)
    if fast is None:
        return model(u, y0)
    yn = fast(model.normalise_u(u), model.normalise_y(y0))
    return torch.cat([y0[:, None], model.denormalise_y(yn[:, 1:])], dim=1)


def _applies(model: StepModel) -> bool:
    if os.environ.get(ENV_SWITCH, "1") == "0":
        return False
    net = model.net if type(model) is LinearPathStepModel else model
    record = architectures.architecture(net.config.arch)
    if record.rollout_cell is None or type(net) is not record.get("model_class"):
        return False  # a subclass may compute something else than the C code
    if any(c.init_window > 1 or c.increment for c in (model.config, net.config)):
        return False  # the encoder's initial state and the increment readout are torch's only
    dtype = next(net.parameters()).dtype
    tensors = [*model.parameters(), *(getattr(model, name) for name in FIXED if net is not model)]
    if dtype not in REALS or any(t.device.type != "cpu" or t.dtype != dtype for t in tensors):
        return False
    return not (model.training and net.config.dropout > 0)  # feedback noise: torch's draws, added in C


def _cell(model: StepModel) -> int:
    return rollout_cells.compiled_cell(model).code


def _weights(model: StepModel) -> list[torch.Tensor]:
    return list(rollout_cells.compiled_cell(model).weights)


def _apply(model: StepModel, library: ctypes.CDLL, un: torch.Tensor, yn0: torch.Tensor) -> torch.Tensor:
    return run(_Rollout, model, library, un, yn0, _weights)


def _header(model: StepModel, B: int, T: int) -> tuple:
    c = model.config
    return (_cell(model), B, T, c.n_u, c.n_y, c.hidden, c.layers, int(c.skip), float(c.skip_scale))


class _Rollout(torch.autograd.Function):
    """Forward: ``nnfmu_rollout_forward``. Backward: ``nnfmu_rollout_backward``. Time-major inside.

    ``model``: the recurrent network; with a linear path, ``fixed`` = its ``[A, B, b, C, d]``, ``z0`` (B, n_z)
    its initial state, and ``weights`` end with ``G``, ``alpha``; else ``fixed`` and ``z0`` are None.
    """

    @staticmethod
    def forward(ctx, model, fixed, library, noise_std, un, yn0, z0, *weights):
        B, T, _ = un.shape
        c, dtype = model.config, weights[0].dtype
        un_t = un.detach().to(dtype).transpose(0, 1).contiguous()
        yn0 = yn0.detach().to(dtype).contiguous()
        z0 = None if z0 is None else z0.detach().to(dtype).contiguous()
        ys_t = un_t.new_empty(T, B, c.n_y)
        keep = any(ctx.needs_input_grad[4:])
        noise = feedback_noise(noise_std, yn0, T)
        shape = (T, c.layers, B, c.hidden)
        hs = un_t.new_empty(shape) if keep else None
        cs = un_t.new_empty(shape) if keep and _cell(model) == rollout_cells.LSTM_CELL else None
        width = library.nnfmu_rollout_saved_width(_cell(model), c.hidden)
        saved = un_t.new_empty(max(T - 1, 0), c.layers, B, width) if keep else None
        ns = un_t.new_empty(max(T - 1, 0), B, c.n_y) if keep and fixed is not None else None
        status = library.nnfmu_rollout_forward(*_header(model, B, T), pointers(weights), ptr(un_t), ptr(yn0),
                                               ptr(noise), ptr(ys_t), ptr(hs), ptr(cs), ptr(saved),
                                               *path_arguments(fixed), ptr(z0), ptr(ns))
        check(status, "free run", B, T)
        if keep:
            ctx.model, ctx.library, ctx.fixed = model, library, fixed
            ctx.save_for_backward(un_t, ys_t, noise, hs, cs, saved, ns, *weights)
        return ys_t.transpose(0, 1).to(un.dtype)

    @staticmethod
    def backward(ctx, gys):
        un_t, ys_t, noise, hs, cs, saved, ns, *weights = ctx.saved_tensors
        T, B, _ = un_t.shape
        grads, gys_t, gyn0, gz0 = backward_buffers(weights, gys, ctx.fixed)
        status = ctx.library.nnfmu_rollout_backward(*_header(ctx.model, B, T), pointers(weights), ptr(un_t),
                                                    ptr(ys_t), ptr(noise), ptr(hs), ptr(cs), ptr(saved), ptr(gys_t),
                                                    pointers(grads), ptr(gyn0), *path_arguments(ctx.fixed), ptr(ns),
                                                    ptr(gz0))
        check(status, "back-propagation through the free run", B, T)
        needed = ctx.needs_input_grad
        return (None, None, None, None, None, gyn0 if needed[5] else None, gz0 if needed[6] else None,
                *(g if need else None for g, need in zip(grads, needed[7:])))
