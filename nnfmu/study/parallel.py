"""Running a study's cells several at a time: in local processes (``--jobs N``) or as Ray tasks (``--address``).

A cell may start once every cell that writes one of its inputs has finished
(the dependency graph follows from the cells' ``inputs`` and ``outputs``); the
rule of :class:`~nnfmu.study.cells.Cell` for skipping what is done is
unchanged, so a parallel run resumes exactly like a sequential one. Cells
marked ``where="driver"`` (reading the user's files, or running a Ray Tune
search, which spreads its own trials) run in this process.

- Local processes (:class:`LocalPool`) run a cell in place: they share the
  study folder with this process.
- Ray tasks (:class:`RayPool`) need no shared file system: a task receives
  the cell's input files (and its unfinished outputs, so a training resumes),
  runs the cell in a temporary folder on its node, and returns the files it
  wrote, which this process writes atomically into the study folder.

Each worker rebuilds the :class:`~nnfmu.study.pipeline.Study` from a plain
description (:func:`study_spec`) with the function the pool was given
(:func:`nnfmu.study.pipeline.study_from_spec`), so nothing but JSON-like data and file bytes
crosses a process or machine boundary.
"""

from __future__ import annotations

import concurrent.futures as cf
import multiprocessing
import tempfile
import time
from pathlib import Path
from typing import Callable, Sequence

from nnfmu.atomic import write_atomic
from nnfmu.study.budgets import Budget, Hyper
from nnfmu.study.cells import Cell, CellLog

#: ``rebuild(spec, folder) -> Study``: :func:`nnfmu.study.pipeline.study_from_spec`, handed in by the study
#: (a module-level function travels to a worker by reference), so this module does not import the pipeline.
Rebuild = Callable[[dict, "str | Path"], object]


def study_spec(study) -> dict:
    """What a worker needs to rebuild ``study`` (plain data only)."""
    return {"system": study.system, "out": str(study.out), "budget": study.budget.to_json(), "seed": study.seed,
            "data": None if study.source is None else str(study.source), "tune": study.tune,
            "device": study.device, "threads": study.threads}


def budget_from_json(doc: dict) -> Budget:
    """Inverse of :meth:`Budget.to_json`."""
    doc = dict(doc)
    doc["hyper"] = {a: Hyper.from_dict(h) for a, h in doc["hyper"].items()}
    doc["tune_grid"] = {a: {k: tuple(v) for k, v in g.items()} for a, g in doc["tune_grid"].items()}
    doc["archs"], doc["strategies"] = tuple(doc["archs"]), tuple(doc["strategies"])
    return Budget(**doc)


def _cell(study, key: str) -> Cell:
    return next(c for c in study.cells() if c.key == key)


def run_in_place(rebuild: Rebuild, spec: dict, key: str) -> str:
    """Run the cell ``key`` of the study folder ``spec['out']`` (a local worker process)."""
    from nnfmu.models.base import torch_threads

    study = rebuild(spec, spec["out"])
    with torch_threads(spec["threads"]):
        return _cell(study, key).run()


def _files(root: Path) -> dict[str, bytes]:
    return {str(p.relative_to(root)): p.read_bytes() for p in sorted(root.rglob("*")) if p.is_file()}


def run_shipped(rebuild: Rebuild, spec: dict, key: str, files: dict[str, bytes]) -> tuple[str, dict[str, bytes]]:
    """Run the cell ``key`` in a temporary study folder holding ``files``; return its note and the files it wrote."""
    from nnfmu.models.base import torch_threads

    with tempfile.TemporaryDirectory(prefix="nnfmu-cell-") as tmp:
        root = Path(tmp)
        for rel, data in files.items():
            (root / rel).parent.mkdir(parents=True, exist_ok=True)
            (root / rel).write_bytes(data)
        before = {rel: (root / rel).stat().st_mtime_ns for rel in files}
        study = rebuild(spec, root)
        with torch_threads(spec["threads"]):
            note = _cell(study, key).run()
        written = {rel: data for rel, data in _files(root).items()
                   if rel not in before or (root / rel).stat().st_mtime_ns != before[rel]}
    return note, written


class LocalPool:
    """``jobs`` worker processes sharing the study folder; each rebuilds the study with ``rebuild``."""

    def __init__(self, jobs: int, rebuild: Rebuild):
        self.executor = cf.ProcessPoolExecutor(max_workers=jobs, mp_context=multiprocessing.get_context("spawn"))
        self.rebuild = rebuild

    def submit(self, spec: dict, cell: Cell, out: Path) -> cf.Future:
        return self.executor.submit(run_in_place, self.rebuild, spec, cell.key)

    def close(self) -> None:
        self.executor.shutdown(wait=True, cancel_futures=True)


class RayPool:
    """Cells as Ray tasks on the cluster this process is connected to; files travel with the tasks."""

    def __init__(self, ray, rebuild: Rebuild, cpus: float = 1.0, gpus: float = 0.0):
        self.ray, self.rebuild = ray, rebuild
        self.task = ray.remote(num_cpus=cpus, num_gpus=gpus, max_retries=0)(run_shipped)

    def submit(self, spec: dict, cell: Cell, out: Path) -> cf.Future:
        paths = [p for p in (*cell.inputs, *cell.outputs) if p.exists()]
        files = {}
        for path in paths:
            found = _files(path) if path.is_dir() else {"": path.read_bytes()}
            files.update({str((path / rel if rel else path).relative_to(out)): b for rel, b in found.items()})
        future: cf.Future = cf.Future()
        ray_future = self.task.remote(self.rebuild, spec, cell.key, files).future()
        ray_future.add_done_callback(lambda f: _settle(future, f, out))
        return future

    def close(self) -> None:
        pass


def _settle(future: cf.Future, ray_future: cf.Future, out: Path) -> None:
    """Write a finished task's files into the study folder, then resolve ``future`` with its note."""
    try:
        note, written = ray_future.result()
        for rel, data in written.items():
            write_atomic(out / rel, lambda tmp, data=data: tmp.write_bytes(data))
        future.set_result(note)
    except BaseException as exc:  # noqa: BLE001 - handed to the waiting loop, which re-raises it
        future.set_exception(exc)


def _start_ready(pending: list, running: dict, finished: set, needs: dict, jobs: int, pool, spec: dict, out: Path,
                 log: CellLog, echo, head) -> None:
    """Start every cell whose inputs' cells have finished, up to ``jobs`` running; skip those done before."""
    skipped = True
    while skipped:  # a skipped cell may make others ready at once
        skipped = False
        for cell in [c for c in pending if needs[c.key] <= finished]:
            if len(running) >= jobs:
                return
            pending.remove(cell)
            if cell.is_done():
                log.skipped.append(cell.key)
                finished.add(cell.key)
                skipped = True
                if echo:
                    echo(f"{head(cell)}: done before, skipped")
                continue
            if echo:
                echo(f"{head(cell)} ...")
            started = time.perf_counter()
            if cell.where == "driver":
                future: cf.Future = cf.Future()
                future.set_result(cell.run())
            else:
                future = pool.submit(spec, cell, out)
            running[future] = (cell, started)


def run_cells_parallel(cells: Sequence[Cell], pool, spec: dict, out: Path, jobs: int,
                       echo: Callable[[str], None] | None = print, log: CellLog | None = None) -> CellLog:
    """Run the cells that are not done, up to ``jobs`` at once, each when its inputs' cells have finished."""
    log = log if log is not None else CellLog()
    producers = {path: cell.key for cell in cells for path in cell.outputs}
    needs = {cell.key: {producers[p] for p in cell.inputs if p in producers} for cell in cells}
    number = {cell.key: i for i, cell in enumerate(cells, 1)}
    width = len(str(len(cells)))
    head = lambda cell: f"[{number[cell.key]:>{width}}/{len(cells)}] {cell.key}"  # noqa: E731
    pending, running, finished = list(cells), {}, set()
    try:
        while pending or running:
            _start_ready(pending, running, finished, needs, jobs, pool, spec, out, log, echo, head)
            if not running:
                if pending:  # nothing runs and nothing can start: a dependency cycle (a bug, not bad input)
                    raise RuntimeError(f"cells {[c.key for c in pending]} wait for each other")
                break
            done, _ = cf.wait(running, return_when=cf.FIRST_COMPLETED)
            for future in done:
                cell, started = running.pop(future)
                note = future.result()
                log.seconds[cell.key] = time.perf_counter() - started
                log.ran.append(cell.key)
                finished.add(cell.key)
                if echo:
                    echo(f"{head(cell)}: {note} ({log.seconds[cell.key]:.1f} s)")
    finally:
        for future in running:
            future.cancel()
    return log
