"""Ctrl-C in the first seconds of ``nnfmu train --seeds K``: one line, status 130, and the truth about what is kept."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time

import pytest
from fmu_cases import oscillator_dataset

import nnfmu.training
from nnfmu.cli import main


def test_a_seed_worker_stopped_before_its_training_began_ends_quietly_with_130(tmp_path):
    fifo = tmp_path / "linear.json"
    os.mkfifo(fifo)  # reading it blocks: the worker waits there, after its imports, until the signal comes
    argv = [sys.executable, "-m", "nnfmu.training.seed_worker", str(tmp_path / "data"), "{}", "{}",
            str(tmp_path / "seed-0.pt"), "cpu", "1", "1", str(fifo)]
    proc = subprocess.Popen(argv, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    writer = _when_read(fifo, proc)  # the worker has opened it: past its imports, with Python's SIGINT handler
    proc.send_signal(signal.SIGINT)
    try:
        try:
            out, err = proc.communicate(timeout=10)
        except subprocess.TimeoutExpired:  # the signal went to another of its threads (torch's): the main one
            os.close(writer)  # still blocks reading, so end the read; Python then raises the pending interrupt
            writer = None
            out, err = proc.communicate(timeout=120)
    finally:
        proc.kill()
        if writer is not None:
            os.close(writer)
    assert proc.returncode == 130 and err == "" and out == ""
    assert not (tmp_path / "seed-0.pt").exists()


def _when_read(fifo, proc, limit_s: float = 120.0) -> int:
    """A write end of ``fifo`` once ``proc`` has it open for reading (it then blocks reading, as nothing is written).

    Opening the write end without blocking fails (ENXIO) until a reader has the FIFO open, so this waits for the
    worker itself, not for a guess at how long its start takes on a busy machine."""
    deadline = time.monotonic() + limit_s
    while True:
        try:
            return os.open(fifo, os.O_WRONLY | os.O_NONBLOCK)
        except OSError:
            if proc.poll() is not None or time.monotonic() > deadline:
                raise
            time.sleep(0.02)


@pytest.fixture
def data(tmp_path):
    return oscillator_dataset(tmp_path / "data")


@pytest.mark.parametrize("written", [[], ["seed-0.pt"]])
def test_an_interrupted_seeds_run_says_what_was_kept(data, tmp_path, capsys, monkeypatch, written):
    out = tmp_path / "m.pt"
    folder = tmp_path / "m.seeds"

    def stopped(*args, **kwargs):  # Ctrl-C while the seeds' workers start
        folder.mkdir()
        for name in written:
            (folder / name).write_bytes(b"a checkpoint")
        raise KeyboardInterrupt

    monkeypatch.setattr(nnfmu.training, "train_seeds", stopped)
    argv = ["train", "--data", str(data), "--arch", "gru", "--hidden", "4", "--epochs", "1", "--seeds", "2",
            "--linear-path", "off", "--quiet", "-o", str(out)]
    assert main(argv) == 130
    captured = capsys.readouterr()
    assert captured.err.strip() == "nnfmu train: interrupted"
    if written:
        assert "the checkpoints of seed-0.pt are kept in" in captured.out and (folder / "seed-0.pt").exists()
    else:
        assert "nothing was kept" in captured.out and not folder.exists()
    assert not out.exists()
