"""Training members one after the other or side by side: the seeds of :func:`nnfmu.training.train_seeds` and
their refits (:mod:`nnfmu.training.refit`).

Each member is a normal resumable :func:`~nnfmu.training.train` into its own checkpoint. A finished member is not
trained again, an unfinished one resumes, and one whose file holds a training of other settings is reported
(:func:`member_state`). Side by side, each member trains in a fresh interpreter
(``python -m nnfmu.training.seed_worker``).
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import tempfile
from pathlib import Path

from nnfmu.data import Dataset, save_dataset
from nnfmu.errors import CheckpointError, ConfigError, TrainingError
from nnfmu.models import ModelConfig, load_checkpoint
from nnfmu.training.config import TrainConfig
from nnfmu.training.resources import usable_cores
from nnfmu.training.trainer import train


def error_file(path: Path) -> Path:
    """Where a seed whose training failed (e.g. a NaN loss) records why; its best weights so far stay in ``path``."""
    return path.with_suffix(".error.txt")


def same_train_config(stored: dict | None, cfg: TrainConfig) -> bool:
    """Whether a checkpoint's stored training settings are ``cfg``'s. A setting added since it was written (absent
    from ``stored``) counts at its default, which is what the code that wrote it did."""
    return stored is not None and {**TrainConfig().to_dict(), **stored} == cfg.to_dict()


def member_state(path: Path, model_config: ModelConfig, cfg: TrainConfig) -> str:
    """'new', 'unfinished' or 'finished' (or failed); ConfigError if the file holds a run of other settings."""
    if not path.exists():
        error_file(path).unlink(missing_ok=True)
        return "new"
    try:
        ckpt = load_checkpoint(path)
    except CheckpointError:  # a damaged member is trained again
        path.unlink()
        return "new"
    if ckpt.get("model_config") != model_config.to_dict() or not same_train_config(ckpt.get("train_config"), cfg):
        raise ConfigError(f"{path} holds a training with other settings; delete {path.parent} or choose another out")
    done = "stop_reason" in (ckpt.get("summary") or {}) or error_file(path).exists()
    return "finished" if done else "unfinished"


def train_member(dataset: Dataset, model_config: ModelConfig, cfg: TrainConfig, path: Path, progress: bool,
                 device="auto", threads: int | None = None, linear=None) -> str:
    """Train (or resume, or skip) one member; returns its stop reason ('done' if it was finished before)."""
    state = member_state(path, model_config, cfg)
    if state == "finished":
        return "done"
    try:
        return train(dataset, model_config, cfg, out=path, resume=state == "unfinished", progress=progress,
                     device=device, threads=threads, linear=linear).stop_reason
    except TrainingError as exc:  # the seed keeps its best weights before the failure, and says why
        error_file(path).write_text(f"{exc}\n")
        return "failed"


def train_in_processes(work: list, jobs: int, device, threads: int | None, linear=None, what: str = "seeds") -> None:
    """Train the members in ``jobs`` worker processes at once (``python -m nnfmu.training.seed_worker``).

    Fresh interpreters, not ``multiprocessing``: the caller's script needs no ``__main__`` guard. The workers run
    in sessions of their own, so a signal to this process (Ctrl-C, SIGTERM) reaches them once, from here: each
    stops after its epoch and keeps its checkpoint, and the same call continues them.
    """
    with tempfile.TemporaryDirectory(prefix="nnfmu-seeds-") as tmp:
        data = Path(tmp) / "dataset"
        save_dataset(work[0][0], data)
        extra = [] if linear is None else [str(linear.save(Path(tmp) / "linear.json"))]
        env = {**os.environ, "OMP_NUM_THREADS": "1"}
        pending, running, failed = list(work), [], []
        try:
            while pending or running:
                while pending and len(running) < jobs:
                    _, model_config, cfg, path, progress = pending.pop(0)
                    args = [sys.executable, "-m", "nnfmu.training.seed_worker", str(data),
                            json.dumps(model_config.to_dict()), json.dumps(cfg.to_dict()), str(path), str(device),
                            str(threads or 1), str(int(progress)), *extra]
                    # a worker that shows its progress bar writes it to this process' stderr
                    running.append((path, subprocess.Popen(args, env=env, stdout=subprocess.DEVNULL,
                                                           stderr=None if progress else subprocess.PIPE, text=True,
                                                           start_new_session=True)))
                path, proc = running[0]
                _, err = proc.communicate()
                running.pop(0)
                if proc.returncode != 0:
                    err = (err or "").strip()
                    failed.append(f"{path.name}: {err.splitlines()[-1] if err else f'exit status {proc.returncode}'}")
        except BaseException:  # stopped here (Ctrl-C, SIGTERM): the workers stop after their epoch, and keep it
            for _, proc in running:
                if proc.poll() is None:
                    proc.send_signal(signal.SIGINT)
            for _, proc in running:
                proc.communicate()
            raise
        if failed:
            raise TrainingError(f"training of {len(failed)} of the {what} failed: {'; '.join(failed)}; the finished "
                                f"{what} are kept, run the same call again to continue")


def planned_jobs(jobs: int | None, k: int) -> int:
    """Processes training ``k`` members at once: ``jobs``, or the usable cores, at most ``k``."""
    if jobs is None:
        jobs = usable_cores()
    if isinstance(jobs, bool) or not isinstance(jobs, int) or jobs < 1:
        raise ConfigError(f"jobs must be a positive integer number of processes, got {jobs!r}")
    return min(jobs, k)


def train_members(work: list, jobs: int, *, device, threads: int | None, linear, overwrite: bool, what: str) -> None:
    """Train every member of ``work`` (``(dataset, model_config, cfg, path, progress)`` each) that is not finished.

    Settings clashes are reported (``overwrite``: cleared) before any training. Raises KeyboardInterrupt when a
    member was stopped (Ctrl-C, SIGTERM): the same call continues it. ``what`` names the members in that message.
    """
    for _, mc, c, path, _ in work:
        try:
            member_state(path, mc, c)
        except ConfigError:
            if not overwrite:
                raise
            path.unlink()
            error_file(path).unlink(missing_ok=True)
    if jobs == 1:
        for item in work:
            if train_member(*item, device=device, threads=threads, linear=linear) in ("SIGINT", "SIGTERM"):
                break
    else:
        train_in_processes(work, jobs, device, threads, linear, what)
    if any(member_state(p, mc, c) != "finished" for (_, mc, c, p, _) in work):
        raise KeyboardInterrupt(f"the training of the {what} was stopped; the finished {what} and the unfinished "
                                f"ones' checkpoints are in {work[0][3].parent}: run the same call again to continue")


def history_seconds(ckpt: dict) -> float:
    """The wall seconds a loaded checkpoint's training took: its history's epochs, validation included."""
    return float(sum(h.get("seconds", 0.0) for h in ckpt.get("history", [])))


def training_seconds(path: Path) -> float:
    """:func:`history_seconds` of the member checkpoint at ``path``."""
    return history_seconds(load_checkpoint(path))


def further_seeds(walls: list, per_wave: int, have: int, most: int, within: float) -> tuple[int, str]:
    """How many seeds the next wave trains (0: none), and why the waves end when they do.

    ``walls``: each wave's wall seconds so far (its slowest member's :func:`training_seconds`: the wave's members
    train side by side); ``per_wave``: the members trained at once; ``have``: the seeds trained; ``most``: the most in
    all; ``within``: the wall seconds the waves may take together. The next wave is expected to take as long as the
    slowest so far, and trains only where it would end within ``within``. The measured seconds, not a clock, decide,
    so a stopped run that is run again trains the same waves.
    """
    spent, expected = sum(walls), max(walls, default=0.0)
    if have >= most:
        return 0, f"the most the plan trains ({most})"
    if spent + expected > within:
        return 0, (f"another wave, at the slowest one's {expected / 60:.1f} minutes, would end after the "
                   f"{within / 60:g} minutes")
    return min(per_wave, most - have), ""
