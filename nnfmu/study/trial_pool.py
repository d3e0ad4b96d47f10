"""The time search's trials in persistent worker processes, stopped early by asynchronous successive halving.

:func:`run_trials` starts one worker (:mod:`nnfmu.study.trial_worker`) a core, each a fresh interpreter in a session
of its own (as :func:`nnfmu.training.train_seeds` runs its seeds: the caller's script needs no ``__main__`` guard,
and a signal reaches the workers once, from here). A worker imports torch and nnfmu and loads the dataset once and
then trains trial after trial, so a core whose trial ended starts the next at once: a fresh process a trial (Ray
Tune's, before) spent seconds of every trial's core on starting and importing, while most trials that
:class:`Halving` stops train for one or two seconds.

After every epoch a worker reports the trial's best validation NRMSE and goes on, without waiting for an answer
(a driver descheduled on busy cores would otherwise hold the workers' cores idle); the driver answers ``stop`` when
:class:`Halving` (ASHA: Li et al., "A system for massively parallel hyperparameter tuning", MLSys 2020) stops a
trial that trails the others at the same epoch, or when the next epoch would end after the search's end, which may
move earlier while the trials run (``end()``). The worker stops after the epoch in which the answer arrives.
"""

from __future__ import annotations

import json
import os
import selectors
import signal
import subprocess
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

import numpy as np

#: Seconds a worker may take to end its epoch after the search's end before it gets SIGINT, then SIGKILL.
LATE_S = 10.0


class Halving:
    """Asynchronous successive halving on the trials' best validation NRMSE so far (lower is better).

    The rungs are the epochs ``grace * factor**k``. A trial reaching a rung goes on if its score is within the best
    ``1 / factor`` of the scores recorded there before it by trials of its group (the first to arrive always goes
    on), as Ray Tune's ``ASHAScheduler`` decides. ``group``: trial -> its group (the time search: its architecture),
    so that trials are compared only with trials that learn at the same pace per epoch; None: one group. The
    ``exempt`` trials (trial 0: the defaults, trained to their own stop) are recorded and never stopped.
    ``stopped``: the trials it stopped.
    """

    def __init__(self, grace: int, factor: int = 2, exempt=(0,), group: Callable[[int], object] | None = None):
        self.grace, self.factor, self.exempt = max(1, int(grace)), factor, set(exempt)
        self.group = group
        self.rungs: dict = {}
        self.stopped: set = set()

    def _is_rung(self, epoch: int) -> bool:
        rung = self.grace
        while rung < epoch:
            rung *= self.factor
        return rung == epoch

    def keep(self, trial: int, epoch: int, score: float) -> bool:
        """Whether ``trial``, at ``epoch`` with best validation NRMSE ``score``, goes on."""
        if not self._is_rung(epoch):
            return True
        recorded = self.rungs.setdefault((None if self.group is None else self.group(trial), epoch), [])
        cutoff = float(np.percentile(recorded, 100.0 / self.factor)) if recorded else None
        recorded.append(score)
        if trial in self.exempt or cutoff is None or score <= cutoff:
            return True
        self.stopped.add(trial)
        return False


@dataclass
class _Worker:
    proc: subprocess.Popen
    log: Path
    trial: int | None = None
    last: dict = field(default_factory=dict)
    buffer: bytes = b""
    interrupted: bool = False

    def send(self, text: str) -> bool:
        try:
            self.proc.stdin.write((text + "\n").encode())
            self.proc.stdin.flush()
            return True
        except (BrokenPipeError, OSError):
            return False

    def close(self) -> None:
        try:
            self.proc.stdin.close()
        except (BrokenPipeError, OSError):
            pass

    def why_ended(self) -> str:
        try:
            lines = self.log.read_text(errors="replace").strip().splitlines()
        except OSError:
            lines = []
        return lines[-1] if lines else f"exit status {self.proc.poll()}"


@dataclass
class Trials:
    """What :func:`run_trials` fills as the trials end: ``records`` (trial -> the worker's record, with ``last``: its
    last epoch report), ``started`` (trials 0 .. started-1 were handed to a worker), ``best`` (``(seconds since the
    start, trial, best validation NRMSE)`` each time the search's best so far fell), ``valid_s`` (trial -> the
    seconds of its last validation free run) and ``scores`` (trial -> its best validation NRMSE so far);
    ``seconds``: how long the trials ran; ``workers``: process id -> ``(CPU seconds, seconds it waited for a core)``
    of each worker, as last read (Linux; empty elsewhere)."""

    records: dict = field(default_factory=dict)
    started: int = 0
    seconds: float = 0.0
    workers: dict = field(default_factory=dict)
    best: list = field(default_factory=list)
    valid_s: dict = field(default_factory=dict)
    scores: dict = field(default_factory=dict)

    def sample(self, workers: list) -> None:
        """Read the workers' CPU time and run-queue wait (``/proc/<pid>/schedstat``: other work on the cores shows
        as wait)."""
        for worker in workers:
            try:
                cpu_ns, wait_ns = open(f"/proc/{worker.proc.pid}/schedstat").read().split()[:2]
            except (OSError, ValueError):
                continue
            self.workers[worker.proc.pid] = (int(cpu_ns) / 1e9, int(wait_ns) / 1e9)

    def note(self, trial: int, report: dict, since: float) -> None:
        self.valid_s[trial] = float(report.get("valid_s", 0.0))
        score = self.scores[trial] = report["best_valid_nrmse"]
        if not self.best or score < self.best[-1][2]:
            self.best.append((time.monotonic() - since, trial, score))


def _start(data: Path, folder: Path, linear: Path | None, k: int) -> _Worker:
    log = folder / f"worker-{k}.log"
    args = [sys.executable, "-m", "nnfmu.study.trial_worker", str(data), str(folder)]
    args += [] if linear is None else [str(linear)]
    with open(log, "ab") as err:
        proc = subprocess.Popen(args, stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=err,
                                env={**os.environ, "OMP_NUM_THREADS": "1"}, start_new_session=True)
    return _Worker(proc, log)


def run_trials(job: Callable[[int], dict | None], *, data: Path, folder: Path, linear: Path | None, cpus: int,
               end: Callable[[], float], min_left_s: float, halving: Halving, trials: Trials,
               on_done: Callable[[int, dict], None] | None = None) -> None:
    """Train trials ``0, 1, ...`` (``job(i)``: the worker's job, or None: none for now) in ``cpus`` workers.

    ``end()``: the :func:`time.monotonic` time the trials end by (asked again after every epoch); no trial starts
    with less than ``min_left_s`` left. A worker with no job waits until another trial ends (which may make one); the
    run ends when no trial runs. ``trials`` is filled as they end (so that a caller stopped by Ctrl-C keeps what is
    done); a trial whose worker died is recorded as failed, with the last line its worker wrote to stderr, and a
    fresh worker takes the next. ``on_done(i, record)`` after each trial.
    """
    run = _Run(job, data, folder, linear, end, min_left_s, halving, trials, on_done)
    try:
        for _ in range(cpus):
            if run.more():
                run.assign(run.spawn())
        sampled = time.monotonic()
        while any(w.trial is not None for w in run.live):
            if time.monotonic() - sampled > 1.0:  # the workers' CPU time, while they are there to be read
                trials.sample(run.live)
                sampled = time.monotonic()
            if time.monotonic() > end() + LATE_S:
                _interrupt([w for w in run.live if w.trial is not None])
            for key, _ in run.selector.select(timeout=1.0):
                run.read(key)
    except BaseException:  # Ctrl-C, SIGTERM: every worker stops after its epoch and keeps its checkpoint
        _interrupt([w for w in run.live if w.proc.poll() is None])
        raise
    finally:
        trials.sample(run.live)
        trials.seconds = time.monotonic() - run.since
        for worker in run.live:
            worker.close()
        _reap(run.live)
        run.selector.close()


class _Run:
    """The state of :func:`run_trials`: the workers, the idle ones, and what to do with a worker's message."""

    def __init__(self, job, data, folder, linear, end, min_left_s, halving, trials, on_done):
        self.job, self.data, self.folder, self.linear, self.end = job, data, folder, linear, end
        self.min_left_s, self.halving, self.trials, self.on_done = min_left_s, halving, trials, on_done
        self.since, self.live, self.idle = time.monotonic(), [], []
        self.selector = selectors.DefaultSelector()

    def more(self) -> bool:
        return self.end() - time.monotonic() >= self.min_left_s

    def spawn(self) -> _Worker:
        worker = _start(self.data, self.folder, self.linear, len(self.live))
        self.selector.register(worker.proc.stdout, selectors.EVENT_READ, worker)
        self.live.append(worker)
        return worker

    def assign(self, worker: _Worker) -> None:
        """The next job to ``worker``, or it waits."""
        spec = self.job(self.trials.started) if self.more() else None
        if spec is None:
            worker.trial = None
            self.idle.append(worker)
            return
        worker.trial, worker.last = self.trials.started, {}
        self.trials.started += 1
        worker.send(json.dumps({**spec, "end": time.time() + (self.end() - time.monotonic())}))

    def ended(self, worker: _Worker, record: dict) -> None:
        """Record ``worker``'s trial; a trial that ended may have made a job for the waiting workers too."""
        i, worker.trial = worker.trial, None
        self.trials.records[i] = {**record, "last": worker.last}
        if self.on_done is not None:
            self.on_done(i, self.trials.records[i])
        waiting, self.idle = self.idle, []
        for other in [worker] + waiting:
            if other.proc.poll() is None:
                self.assign(other)
        if worker.proc.poll() is not None and self.more():  # a worker died: a fresh one in its place
            self.assign(self.spawn())

    def read(self, key) -> None:
        """Handle what a worker wrote: an epoch's report (answered), a trial's end, or its own end."""
        worker = key.data
        chunk = os.read(key.fd, 65536)
        if not chunk:  # the worker ended; in the middle of a trial, the trial failed
            self.selector.unregister(key.fileobj)
            worker.proc.wait()
            if worker.trial is not None:
                self.ended(worker, {"status": "failed", "error": f"its worker ended: {worker.why_ended()}",
                                    "cpu_s": worker.last.get("cpu_s")})
            return
        worker.buffer += chunk
        while b"\n" in worker.buffer:
            line, worker.buffer = worker.buffer.split(b"\n", 1)
            message = json.loads(line)
            if "done" in message:
                self.ended(worker, message["done"])
                continue
            worker.last = message
            self.trials.note(worker.trial, message, self.since)
            keep = self.halving.keep(worker.trial, message["epoch"], message["best_valid_nrmse"])
            next_epoch = message.get("seconds", 0.0) + message.get("valid_s", 0.0)
            if not (keep and time.monotonic() + next_epoch <= self.end()):
                worker.send(f"stop {worker.trial}")


def _interrupt(workers: list) -> None:
    """SIGINT, once (a second would abort the epoch and lose it): the worker's trial stops after its epoch."""
    for worker in workers:
        if worker.proc.poll() is None and not worker.interrupted:
            worker.interrupted = True
            worker.proc.send_signal(signal.SIGINT)


def _reap(workers: list) -> None:
    """Wait for the workers to exit (they do once their stdin is closed); kill one that does not within LATE_S."""
    deadline = time.monotonic() + LATE_S
    for worker in workers:
        try:
            worker.proc.wait(timeout=max(0.1, deadline - time.monotonic()))
        except subprocess.TimeoutExpired:
            worker.proc.kill()
            worker.proc.wait()
        for stream in (worker.proc.stdout,):
            stream.close()
