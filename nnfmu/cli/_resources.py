"""``--device`` and ``--threads``: the options of train, tune and reproduce that say where training runs."""

from __future__ import annotations

import argparse


def add_resource_options(p: argparse.ArgumentParser, *, what: str = "each training") -> None:
    """Add ``--device auto|cpu|cuda[:N]`` and ``--threads N`` (see :mod:`nnfmu.training.resources`)."""
    p.add_argument("--device", default="auto", metavar="auto|cpu|cuda",
                   help=f"where {what} runs: auto (a CUDA GPU if torch sees one, else the CPU; default), cpu, "
                        "cuda or cuda:N")
    p.add_argument("--threads", type=int, default=None, metavar="N",
                   help=f"intra-op torch threads of {what} (default 1: measured fastest for these small "
                        "networks; see docs/scaling.md)")


def check_resource_options(args: argparse.Namespace):
    """The resolved ``torch.device``, after checking ``--threads``: bad values fail before any work is done."""
    from nnfmu.training.resources import check_threads, resolve_device

    check_threads(args.threads)
    return resolve_device(args.device)
