"""Resumable cells: each step of a study writes files, and a step whose files are up to date is skipped.

A :class:`Cell` names its output files and the files it depends on. It is
*done* when every output exists and none is older than an input (the rule of
``make``), or when its own ``done`` test says so; otherwise :func:`run_cells`
runs it. Outputs are written atomically by the functions the cells call
(dataset folders, checkpoints, FMUs, score files), so an interrupted cell
leaves either its old result or nothing, never half a file. A deleted or
outdated output is therefore simply redone, and so is everything downstream of it.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Sequence

import numpy as np


@dataclass(frozen=True)
class Cell:
    """One resumable step of a study.

    Attributes
    ----------
    key : str
        Name shown in the progress lines, e.g. ``"train gru parallel"``.
    outputs : tuple of Path
        Files (or folders) the step writes.
    inputs : tuple of Path
        Files the step reads; an output older than one of them is outdated.
    run : callable
        ``run() -> str``: does the work, returns a short note for the progress line.
    done : callable, optional
        ``done() -> bool``: an extra test for completeness (e.g. a training checkpoint that
        was written after every epoch but whose run has not finished yet is not done).
    where : {'any', 'driver'}
        Where a parallel run (:mod:`nnfmu.study.parallel`) may run it: in any worker, or only in
        the process that drives the study (cells reading the user's files, Ray Tune searches).
    """

    key: str
    outputs: tuple[Path, ...]
    inputs: tuple[Path, ...]
    run: Callable[[], str]
    done: Callable[[], bool] | None = None
    where: str = "any"

    def is_done(self) -> bool:
        if not all(p.exists() for p in self.outputs):
            return False
        newest_input = max((_mtime(p) for p in self.inputs if p.exists()), default=-np.inf)
        if min(_mtime(p) for p in self.outputs) < newest_input:
            return False
        return self.done() if self.done is not None else True


def _mtime(path: Path) -> float:
    """Modification time of a file, or of a folder's newest direct entry (a dataset folder)."""
    if path.is_dir():
        return max((p.stat().st_mtime for p in path.iterdir()), default=path.stat().st_mtime)
    return path.stat().st_mtime


@dataclass
class CellLog:
    """What :func:`run_cells` did: the keys of the cells that ran and of those skipped as done."""

    ran: list[str] = field(default_factory=list)
    skipped: list[str] = field(default_factory=list)
    seconds: dict[str, float] = field(default_factory=dict)


def run_cells(cells: Sequence[Cell], log: CellLog | None = None,
              echo: Callable[[str], None] | None = print) -> CellLog:
    """Run every cell that is not done, in order, printing one line per cell; returns the log.

    Cells are checked one at a time, just before they would run, so that a cell
    redone upstream makes the cells that depend on it outdated.
    """
    log = log if log is not None else CellLog()
    width = len(str(len(cells)))
    for i, cell in enumerate(cells, 1):
        head = f"[{i:>{width}}/{len(cells)}] {cell.key}"
        if cell.is_done():
            log.skipped.append(cell.key)
            if echo:
                echo(f"{head}: done before, skipped")
            continue
        if echo:
            echo(f"{head} ...")
        t0 = time.perf_counter()
        note = cell.run()
        log.seconds[cell.key] = time.perf_counter() - t0
        log.ran.append(cell.key)
        if echo:
            echo(f"{head}: {note} ({log.seconds[cell.key]:.1f} s)")
    return log
