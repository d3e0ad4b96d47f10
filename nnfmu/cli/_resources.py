"""``--device`` and ``--threads``: the options of train, tune and reproduce that say where training runs.

One dialect (:mod:`nnfmu.training.resources`): ``auto``, ``cpu``, ``cuda`` or ``cuda:N``, read by
:func:`~nnfmu.training.resources.device_name` and resolved by ``resolve_device`` for every command.
"""

from __future__ import annotations

import argparse

DEVICE_METAVAR = "auto|cpu|cuda[:N]"


def add_device_option(p: argparse.ArgumentParser, *, what: str = "each training", extra: str = "") -> None:
    """Add ``--device auto|cpu|cuda[:N]`` (``extra``: a sentence of the command's own)."""
    p.add_argument("--device", default="auto", metavar=DEVICE_METAVAR,
                   help=f"where {what} runs: auto (a CUDA GPU if torch sees one, else the CPU; default), cpu, "
                        f"cuda or cuda:N{extra}")


def add_resource_options(p: argparse.ArgumentParser, *, what: str = "each training") -> None:
    """Add ``--device auto|cpu|cuda[:N]`` and ``--threads N`` (see :mod:`nnfmu.training.resources`)."""
    add_device_option(p, what=what)
    p.add_argument("--threads", type=int, default=None, metavar="N",
                   help=f"intra-op torch threads of {what} (default 1: measured fastest for these small "
                        "networks; see docs/scaling.md)")


def check_resource_options(args: argparse.Namespace, *, say: bool = True):
    """The resolved ``torch.device``, after checking ``--threads``: bad values fail before any work is done.

    ``say``: print which device the run uses, and why (``device: cpu (auto: no CUDA device)``).
    """
    from nnfmu.training.resources import check_threads, describe_device, resolve_device

    check_threads(args.threads)
    device = resolve_device(args.device)
    if say:
        print(f"device: {describe_device(args.device)}", flush=True)
    return device
