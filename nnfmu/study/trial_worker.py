"""A worker of the time search (:mod:`nnfmu.study.trial_pool`): one process that trains trial after trial.

``python -m nnfmu.study.trial_worker DATASET_DIR FOLDER [LINEAR.json]``

The process loads torch, nnfmu, the dataset (its validation split fixed; its test split dropped) and the linear model once,
then reads one job a line on stdin until stdin closes. A job is a JSON object: ``trial`` (its index),
``model_config`` and ``train_config`` (dicts) and ``end`` (a :func:`time.time`; no epoch is started that would end
after it). The trial is :func:`nnfmu.training.train` into ``FOLDER/trial-<i>.pt``, on the CPU with one thread.
After every epoch the worker writes one JSON line to its stdout (``epoch``, ``valid_nrmse``, ``best_valid_nrmse``,
``cpu_s``, ``seconds``: of its training, ``valid_s``: of its validation) and goes on without waiting: the trial stops
after the epoch in which the line ``stop <trial>`` arrives (the driver's successive halving, or the search's end),
so a busy driver never holds a worker's core idle. When the trial ends the worker writes ``{"done": record}``
(``status``, ``error``, ``cpu_s``: the CPU seconds the trial took). Anything else printed goes to stderr.
"""

from __future__ import annotations

import json
import os
import select
import sys
import time
from pathlib import Path

from nnfmu.data import load_dataset
from nnfmu.errors import NnfmuError, TrainingError
from nnfmu.linear import load_linear
from nnfmu.models import ModelConfig
from nnfmu.study.tune import _finite
from nnfmu.training import StopTraining, TrainConfig, train


def run_trial(job: dict, dataset, linear, folder: Path, ask) -> dict:
    """Train one job (module docstring); ``ask(report) -> bool``: whether to go on after an epoch."""
    record = {"status": "not started: the search's time was up", "error": None, "cpu_s": 0.0}
    seconds = job["end"] - time.time()
    if seconds < 1.0:
        return record
    train_config = TrainConfig.from_dict(job["train_config"])
    train_config = train_config.replace(max_minutes=min(train_config.max_minutes or seconds / 60.0, seconds / 60.0))
    cpu0, stopped, last = time.process_time(), [], [time.monotonic()]

    def report(epoch: int, metrics: dict) -> None:
        now = time.monotonic()
        valid_s, last[0] = max(0.0, now - last[0] - metrics["seconds"]), now
        go = ask({"epoch": epoch, "valid_nrmse": _finite(metrics["valid_nrmse"]),
                  "best_valid_nrmse": _finite(metrics["best_valid_nrmse"]), "cpu_s": time.process_time() - cpu0,
                  "seconds": metrics["seconds"], "valid_s": valid_s})
        last[0] = time.monotonic()  # writing the report is not the next epoch's validation
        if not go:
            stopped.append(epoch)
            raise StopTraining
        if time.time() + metrics["seconds"] + valid_s > job["end"]:  # the next epoch would end past the end
            raise StopTraining

    try:
        result = train(dataset, ModelConfig.from_dict(job["model_config"]), train_config,
                       out=folder / f"trial-{job['trial']}.pt", callback=report, device="cpu", threads=1,
                       linear=linear)
        record["status"] = ("stopped" if stopped else "time-budget" if result.stop_reason == "callback"
                            else result.stop_reason)
    except TrainingError as exc:  # a diverging point is a bad score, not a failed search
        record.update(status="diverged", error=str(exc).split(";")[0])
    except NnfmuError as exc:
        record.update(status="failed", error=str(exc))
    record["cpu_s"] = time.process_time() - cpu0
    return record


class _Inbox:
    """The driver's lines on stdin, read without blocking between epochs (a job when idle, ``stop <trial>``)."""

    def __init__(self):
        self.buffer, self.closed = b"", False

    def _read(self, wait: bool) -> None:
        if self.closed or not (wait or select.select([0], [], [], 0)[0]):
            return
        chunk = os.read(0, 65536)
        self.closed = not chunk
        self.buffer += chunk

    def _take(self) -> str | None:
        line, sep, rest = self.buffer.partition(b"\n")
        if not sep:
            return None
        self.buffer = rest
        return line.decode()

    def pending(self) -> list[str]:
        """The lines that have arrived, without waiting."""
        self._read(wait=False)
        lines = []
        while (line := self._take()) is not None:
            lines.append(line)
        return lines

    def next_job(self) -> dict | None:
        """The next job, waiting for it (``stop`` lines for trials that have ended are passed over); None at EOF."""
        while True:
            line = self._take()
            if line is not None:
                if line.startswith("{"):
                    return json.loads(line)
                continue
            if self.closed:
                return None
            self._read(wait=True)


def main(argv: list[str]) -> int:
    data, folder, *linear = argv
    channel = os.fdopen(os.dup(1), "w", buffering=1)  # the driver's pipe; whatever else prints goes to stderr
    os.dup2(2, 1)
    sys.stdout = sys.stderr
    dataset, start = load_dataset(data), load_linear(linear[0]) if linear else None
    dataset = dataset.replace(splits={k: v for k, v in dataset.splits.items() if k != "test"})  # chosen without it
    inbox = _Inbox()
    while (job := inbox.next_job()) is not None:
        stop = f"stop {job['trial']}"

        def ask(report: dict) -> bool:  # the driver's answer to an earlier epoch may still be on its way: no wait
            channel.write(json.dumps(report) + "\n")
            return stop not in inbox.pending() and not inbox.closed

        record = run_trial(job, dataset, start, Path(folder), ask)
        channel.write(json.dumps({"done": record}) + "\n")
    return 0


if __name__ == "__main__":
    try:
        sys.exit(main(sys.argv[1:]))
    except KeyboardInterrupt:  # the driver stopped the search while this worker waited for its next job
        sys.exit(130)
