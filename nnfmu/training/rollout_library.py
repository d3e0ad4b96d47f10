"""The compiled free runs' C libraries and the ctypes plumbing of their calls (:mod:`nnfmu.training.compiled_rollout`).

``rollout.c`` (the recurrent cells) and ``window_rollout.c`` (the TCN and the MLP) share ``rollout_kernels.h``, which
:func:`source` pastes in place of the include line, so that a cached library is keyed by all it was compiled from.
"""

from __future__ import annotations

import ctypes
import functools
import warnings
from pathlib import Path
from typing import Callable

import torch

from nnfmu.errors import FmuBuildError, SimulationError
from nnfmu.models.base import StepModel
from nnfmu.models.linear_path import LinearPathStepModel

_HERE = Path(__file__).parent
_FLAGS = ("-O3", "-march=native", "-fno-math-errno", "-fopenmp-simd", "-fPIC", "-shared")
REALS = {torch.float32: "float", torch.float64: "double"}
FIXED = ("lin_A", "lin_B", "lin_b", "lin_C", "lin_d")  # the linear path's fixed model, in the C files' order


def pointers(tensors) -> ctypes.Array:
    """A C array of the tensors' data pointers (``const real **``)."""
    return (ctypes.c_void_p * len(tensors))(*(t.data_ptr() for t in tensors))


def path_arguments(fixed) -> tuple:
    """The linear path's ``n_z, lin`` arguments (``0, NULL`` without a path); ``fixed``: ``[A, B, b, C, d]`` or None."""
    return (0, None) if fixed is None else (fixed[0].shape[0], pointers(fixed))


def ptr(t: torch.Tensor | None) -> ctypes.c_void_p:
    return ctypes.c_void_p(None if t is None else t.data_ptr())


def run(function, model: StepModel, library: ctypes.CDLL, un: torch.Tensor, yn0: torch.Tensor, weights_of):
    """``function.apply`` (a compiled free run's autograd Function) on ``model``, or on the network of its linear path
    with the path's fixed model, initial state and correction gains; ``weights_of(network)``: its weights in the C
    file's order. The feedback noise is the model's own in training (a path's, which its network's loop adds)."""
    noise = model.feedback_noise if model.training else 0.0
    if type(model) is not LinearPathStepModel:
        return function.apply(model, None, library, noise, un, yn0, None, *weights_of(model))
    fixed = [getattr(model, name).detach().contiguous() for name in FIXED]
    z0 = model._z0(yn0, un[:, 0])  # torch: its gradient reaches yn0 through lin_Ky
    return function.apply(model.net, fixed, library, noise, un, yn0, z0, *weights_of(model.net), model.lin_G,
                          model.alpha)


def feedback_noise(std: float, yn0: torch.Tensor, T: int) -> torch.Tensor | None:
    """The noise on the fed-back output of a free run of T steps, (T - 1, B, n_y), or None for ``std`` 0: drawn as
    the torch loop draws it (``StepModel._feedback``: one ``randn_like`` of (B, n_y) a step, in order), so that the
    C code computes the numbers torch would for the same seed."""
    if not std:
        return None
    draws = [std * torch.randn_like(yn0) for _ in range(T - 1)]
    return torch.stack(draws) if draws else yn0.new_empty(0, *yn0.shape)


def backward_buffers(weights, gys: torch.Tensor, fixed) -> tuple:
    """What a backward call fills: the weights' gradients (zeroed), ``dL/dys`` time-major (T, B, n_y) in the weights'
    dtype, and the outputs ``dL/dyn0`` (B, n_y) and ``dL/dz0`` (B, n_z; None without a linear path)."""
    grads = [torch.zeros_like(w) for w in weights]
    gys_t = gys.to(weights[0].dtype).transpose(0, 1).contiguous()
    gyn0 = gys_t.new_empty(gys_t.shape[1:])
    gz0 = None if fixed is None else gys_t.new_empty(gys_t.shape[1], fixed[0].shape[0])
    return grads, gys_t, gyn0, gz0


def check(status: int, what: str, B: int, T: int) -> None:
    """SimulationError when a C call says its memory ran out (status != 0)."""
    if status != 0:
        raise SimulationError(f"the compiled {what} ran out of memory at batch {B} x {T} steps; "
                              "use a smaller batch_size or truncate the trajectories")


def or_none(make: Callable[[], ctypes.CDLL], what: str) -> ctypes.CDLL | None:
    """``make()``, or None with a RuntimeWarning that ``what`` runs in torch, when it cannot be compiled or loaded
    (callers cache the answer, so the warning comes once)."""
    try:
        return make()
    except (FmuBuildError, OSError) as exc:
        warnings.warn(f"{what} runs in torch instead of compiled C (slower, same values): "
                      f"{str(exc).splitlines()[0]}", RuntimeWarning, stacklevel=5)
        return None


@functools.lru_cache(maxsize=None)
def library_or_none(dtype: torch.dtype, stem: str = "rollout") -> ctypes.CDLL | None:
    """:func:`library`, or None with a one-time RuntimeWarning when it cannot be compiled or loaded."""
    return or_none(lambda: library(dtype, stem), "the free run")


def source(c_file: Path) -> str:
    """``c_file`` with ``rollout_kernels.h`` pasted in place of its include line: what is compiled (and hashed)."""
    kernels = (_HERE / "rollout_kernels.h").read_text()
    return c_file.read_text().replace('#include "rollout_kernels.h"', kernels)


def compiled(dtype: torch.dtype, c_file: Path) -> ctypes.CDLL:
    """``c_file`` (a C file that includes ``rollout_kernels.h``) compiled for ``dtype`` once per machine (cached by
    source, flags and CPU, like the compiled physics: ``$NNFMU_CACHE_DIR``) and loaded; its entries' argtypes are the
    caller's to set. FmuBuildError or OSError when it cannot be compiled or loaded."""
    from nnfmu import cbuild

    flags = (*_FLAGS, f"-DNNFMU_REAL={REALS[dtype]}")
    # no libmvec (not glibc on x86-64): scalar exp and tanh, same values
    target = cbuild.build_cached(f"{c_file.stem}_{REALS[dtype]}", source(c_file), flags=flags,
                                 link_choices=(("-lmvec", "-lm"), ("-lm",)),
                                 what=f"compiling the free run ({c_file.parent.name}/{c_file.name})")
    return cbuild.load(target)


def library(dtype: torch.dtype, stem: str = "rollout") -> ctypes.CDLL:
    """``<stem>.c`` of this folder (``rollout``: the recurrent cells, ``window_rollout``: the TCN and the MLP),
    :func:`compiled` for ``dtype``, with its entries' argtypes."""
    lib = compiled(dtype, _HERE / f"{stem}.c")
    path = [ctypes.c_int] + [ctypes.c_void_p] * 3
    if stem == "window_rollout":
        header = [ctypes.c_int] * 10 + [ctypes.c_double]
        lib.nnfmu_window_forward.argtypes = header + [ctypes.c_void_p] * 10 + path
        lib.nnfmu_window_backward.argtypes = header + [ctypes.c_void_p] * 11 + path
        entries = (lib.nnfmu_window_forward, lib.nnfmu_window_backward)
    else:
        header = [ctypes.c_int] * 8 + [ctypes.c_double]
        lib.nnfmu_rollout_forward.argtypes = header + [ctypes.c_void_p] * 8 + path
        lib.nnfmu_rollout_backward.argtypes = header + [ctypes.c_void_p] * 10 + path
        lib.nnfmu_rollout_saved_width.argtypes = [ctypes.c_int, ctypes.c_int]
        entries = (lib.nnfmu_rollout_forward, lib.nnfmu_rollout_backward, lib.nnfmu_rollout_saved_width)
    for entry in entries:
        entry.restype = ctypes.c_int
    return lib
