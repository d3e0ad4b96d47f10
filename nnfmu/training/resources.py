"""Where a training runs and on how many threads: the device and the thread policy.

Device. ``"auto"`` takes the first CUDA device when torch sees one and the CPU
otherwise; ``"cpu"`` and ``"cuda"`` (or ``"cuda:N"``) ask for one. Asking for
CUDA where there is none raises :class:`~nnfmu.errors.ConfigError` (one line,
exit status 2 on the command line). Every command reads ``--device`` through
this module: :func:`device_name` checks the words, :func:`resolve_device` picks
the torch device on this machine, :func:`describe_device` says which and why
(the ``device: ...`` line of ``nnfmu train``), and :func:`gpus_per_training`
turns the words into the GPUs Ray reserves for one trial or study cell. Under
Ray a training that reserved a GPU sees only that one, renumbered ``cuda:0``
(Ray sets ``CUDA_VISIBLE_DEVICES``): ``cuda:N`` of a local search pins the
local Ray instance to this machine's GPU N instead (:func:`cuda_visible`). The model, the training data and the
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


def device_name(device: str | torch.device | None = "auto") -> str:
    """``device`` as one of ``auto``, ``cpu``, ``cuda``, ``cuda:N`` (lower case; None means auto), checked
    without looking for a GPU (a cluster's driver may have none).

    Raises
    ------
    ConfigError
        For an unknown name or a bad index.
    """
    name = "auto" if device is None else str(device).strip().lower()
    if name in DEVICES:
        return name
    head, sep, index = name.partition(":")
    if head == "cuda" and sep and index.isdigit() and index.isascii():
        return f"cuda:{int(index)}"
    if head == "cuda":
        raise ConfigError(f"device {name!r} is not a valid CUDA device name; use cuda or cuda:N (N = 0, 1, ...)")
    raise ConfigError(f"unknown device {device!r}; choose one of {', '.join(DEVICES)} (or cuda:N)")


def resolve_device(device: str | torch.device | None = "auto") -> torch.device:
    """The torch device for ``"auto"``, ``"cpu"``, ``"cuda"``, ``"cuda:N"`` (None means auto).

    Raises
    ------
    ConfigError
        For an unknown name, or CUDA asked for where torch sees no CUDA device.
    """
    name = device_name(device)
    if name == "auto":
        return torch.device("cuda" if torch.cuda.is_available() else "cpu")
    if name == "cpu":
        return torch.device("cpu")
    if name.startswith("cuda"):
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
    raise AssertionError(name)  # device_name admits nothing else


def describe_device(device: str | torch.device | None = "auto") -> str:
    """The device a training on this machine uses and why, e.g. ``"cpu (auto: no CUDA device)"``,
    ``"cuda (auto: torch sees 2 CUDA devices; the first)"`` or ``"cuda:1 (asked for)"``."""
    name = device_name(device)
    resolved = resolve_device(name)
    if name != "auto":
        return f"{resolved} (asked for)"
    if resolved.type == "cpu":
        return "cpu (auto: no CUDA device)"
    count = torch.cuda.device_count()
    return f"{resolved} (auto: torch sees {count} CUDA device{'s' if count != 1 else ''}; the first)"


def gpus_per_training(device: str | None, gpus_available: float, gpus: float | None = None) -> float:
    """GPUs Ray reserves for one training (a tune trial, a study cell) asked to run on ``device``.

    ``cpu``: none; ``cuda`` or ``cuda:N``: one; ``auto``: one where the cluster (or the local Ray
    instance) has ``gpus_available >= 1``, else none. ``gpus`` (``--gpus-per-trial``; None: the
    above) overrides the count, but not against the device: a GPU for a CPU training would sit
    idle, and a CUDA training without one sees no GPU (Ray hides the unreserved ones).

    Raises
    ------
    ConfigError
        For ``cpu`` with ``gpus > 0`` or ``cuda[:N]`` with ``gpus == 0``.
    """
    name = device_name(device)
    if gpus is None:
        return 0.0 if name == "cpu" or (name == "auto" and gpus_available < 1) else 1.0
    if name == "cpu" and gpus > 0:
        raise ConfigError(f"--device cpu with --gpus-per-trial {gpus:g}: a CPU training leaves its GPU idle; "
                          "drop --gpus-per-trial, or use --device cuda (or auto)")
    if name.startswith("cuda") and gpus == 0:
        raise ConfigError(f"--device {name} with --gpus-per-trial 0: a trial without a GPU sees none; "
                          "drop --gpus-per-trial 0, or use --device cpu")
    return float(gpus)


def check_ray_device(device: str | None, gpus: float | None, address: str | None = None) -> str:
    """``device`` in the one dialect, checked against ``gpus`` (``--gpus-per-trial``) as in
    :func:`gpus_per_training`, and refused as ``cuda:N`` with ``address``: on a cluster Ray, not
    the driver, picks each training's GPU, so an index of this machine means nothing there."""
    name = device_name(device)
    gpus_per_training(name, 0, gpus)
    if address and cuda_visible(name) is not None:
        raise ConfigError(f"--device {name} names a GPU of this machine, but the trials run on the cluster at "
                          f"{address}, where Ray picks each trial's GPU; use --device cuda")
    return name


def cuda_visible(device: str | None) -> str | None:
    """``"N"`` for ``cuda:N``: the ``CUDA_VISIBLE_DEVICES`` that gives a local Ray instance this machine's
    GPU N alone (a trial then sees it as ``cuda:0``); None for any other device."""
    name = device_name(device)
    return name.partition(":")[2] if name.startswith("cuda:") else None


def usable_cores() -> int:
    """The CPU cores this process may run on (its affinity where the system says, else the machine's count)."""
    return len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)


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


def adamw(params, *, lr: float, weight_decay: float) -> torch.optim.AdamW:
    """AdamW with torch's fused kernel where it has one for these tensors, the default implementation otherwise.

    The fused kernel updates every parameter in one call instead of about ten operations per
    parameter tensor: for the small networks here it cut the optimiser's time per batch from
    540 to 160 microseconds (docs/scaling.md). Same update, rounding aside.
    """
    params = list(params)
    try:
        return torch.optim.AdamW(params, lr=lr, weight_decay=weight_decay, fused=True)
    except (RuntimeError, TypeError, ValueError):  # an older torch, or a device or dtype without the kernel
        return torch.optim.AdamW(params, lr=lr, weight_decay=weight_decay)


def cpu_state(state: dict) -> dict:
    """A state dict (nested dicts and lists too) with every tensor on the CPU: device-independent checkpoints."""
    if isinstance(state, torch.Tensor):
        return state.detach().cpu()
    if isinstance(state, dict):
        return {k: cpu_state(v) for k, v in state.items()}
    if isinstance(state, (list, tuple)):
        return type(state)(cpu_state(v) for v in state)
    return state
