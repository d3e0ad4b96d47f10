"""Where a training runs and on how many threads: the device and the thread policy.

Device. ``"auto"`` takes the first CUDA device when torch sees one and the CPU
otherwise; ``"cpu"`` and ``"cuda"`` (or ``"cuda:N"``) ask for one. Asking for
CUDA where there is none raises :class:`~nnfmu.errors.ConfigError` (one line,
exit status 2 on the command line). The model, the training data and the
validation data move to the device once; checkpoints always hold CPU tensors,
so a model trained on a GPU loads, exports and resumes on a machine without one.

Threads. A training or a free run uses ONE intra-op thread unless told
otherwise (``threads=N``, ``--threads N``). The small networks of this toolkit
step through thousands of tiny operations per batch, and splitting each over
threads only adds synchronisation. Measured with
``benchmarks/train_throughput.py`` (GRU-64, the valve paper shape, process CPU
time, interleaved; figures in docs/scaling.md): on a busy 2-core machine one
thread was 9-18x faster than torch's default of all cores, and on an idle one
a second thread never gained more than it cost in CPU time, for every batch
size up to the whole 900-trajectory epoch. Parallelism goes across trainings
instead (``nnfmu reproduce --jobs N``, Ray Tune trials). On a CUDA device the
thread count only affects the host side and is left at one too.
"""

from __future__ import annotations

import os

import torch

from nnfmu.errors import ConfigError

DEVICES = ("auto", "cpu", "cuda")
DEFAULT_THREADS = 1


def resolve_device(device: str | torch.device | None = "auto") -> torch.device:
    """The torch device for ``"auto"``, ``"cpu"``, ``"cuda"``, ``"cuda:N"`` (None means auto).

    Raises
    ------
    ConfigError
        For an unknown name, or CUDA asked for where torch sees no CUDA device.
    """
    if isinstance(device, torch.device):
        device = str(device)
    name = "auto" if device is None else str(device).strip().lower()
    if name == "auto":
        return torch.device("cuda" if torch.cuda.is_available() else "cpu")
    if name == "cpu":
        return torch.device("cpu")
    if name == "cuda" or name.startswith("cuda:"):
        if not torch.cuda.is_available():
            build = "a CPU-only build" if torch.version.cuda is None else f"built for CUDA {torch.version.cuda}"
            raise ConfigError(f"device {name!r} asked for, but torch ({torch.__version__}, {build}) sees no CUDA "
                              "device; use --device cpu (or auto, which falls back to the CPU)")
        try:
            resolved = torch.device(name)
        except RuntimeError as exc:
            raise ConfigError(f"device {name!r} is not a valid CUDA device name ({exc}); use cuda or cuda:N") from exc
        if resolved.index is not None and resolved.index >= torch.cuda.device_count():
            raise ConfigError(f"device {name!r} asked for, but torch sees {torch.cuda.device_count()} CUDA "
                              f"device(s); use cuda:0 .. cuda:{torch.cuda.device_count() - 1}")
        return resolved
    raise ConfigError(f"unknown device {device!r}; choose one of {', '.join(DEVICES)} (or cuda:N)")


def check_threads(threads: int | None) -> int:
    """``threads`` as a positive int (None: the policy's :data:`DEFAULT_THREADS`); ConfigError otherwise."""
    if threads is None:
        return DEFAULT_THREADS
    if isinstance(threads, bool) or not isinstance(threads, int) or threads < 1:
        raise ConfigError(f"threads must be a positive integer (intra-op threads of one training), got {threads!r}")
    cores = os.cpu_count() or 1
    if threads > cores:
        raise ConfigError(f"threads={threads} exceeds the {cores} CPU cores of this machine; use at most {cores}")
    return threads


def cpu_state(state: dict) -> dict:
    """A state dict (nested dicts and lists too) with every tensor on the CPU: device-independent checkpoints."""
    if isinstance(state, torch.Tensor):
        return state.detach().cpu()
    if isinstance(state, dict):
        return {k: cpu_state(v) for k, v in state.items()}
    if isinstance(state, (list, tuple)):
        return type(state)(cpu_state(v) for v in state)
    return state
