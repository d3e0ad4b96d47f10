"""The CLI contract (nnfmu.cli): one line and status 2 on errors, nothing left behind, sizes checked first,
130/143 on SIGINT/SIGTERM, stale temporary files removed, hostile checkpoints refused with a safe message."""

from __future__ import annotations

import contextlib
import os
import resource
import signal
import stat
import subprocess
import sys
import threading
import time
from pathlib import Path
from unittest import mock

import pytest
import torch
from fmu_cases import oscillator_dataset

from nnfmu.atomic import write_atomic
from nnfmu.cli import main as nnfmu_main
from nnfmu.export.__main__ import main as export_main
from nnfmu.models import ModelConfig, build_model, save_checkpoint

pytestmark = pytest.mark.usefixtures("one_thread")
TRAIN = ["--arch", "gru", "--hidden", "4", "--epochs", "1", "--batch-size", "4", "--quiet"]


@pytest.fixture(scope="module")
def work(tmp_path_factory):
    """A folder with a tiny dataset, a checkpoint, an FMU and a regular file in the way."""
    root = tmp_path_factory.mktemp("contract")
    data = oscillator_dataset(root / "data")
    net = build_model(ModelConfig(arch="gru", n_u=1, n_y=2, hidden=4),
                      {"name": "osc_gru", "Ts": 0.01, "inputs": [{"name": "force", "unit": "N"}],
                       "outputs": [{"name": "pos", "unit": "m"}, {"name": "vel", "unit": "m/s"}]})
    ckpt = save_checkpoint(root / "gru.pt", net)
    assert nnfmu_main(["linear", "--data", str(data), "--order", "2", "--no-refine", "-o", str(root / "lin.fmu")]) == 0
    (root / "afile").write_text("a regular file where a folder should be")
    return {"root": root, "data": data, "ckpt": ckpt, "fmu": root / "lin.fmu", "afile": root / "afile"}


def assert_one_line_error(capsys, prog: str, *words: str) -> str:
    """The error is one line (after any progress bar, which tqdm redraws with carriage returns)."""
    err = capsys.readouterr().err.strip().split("\r")[-1]
    assert "\n" not in err and err.startswith(f"{prog}: error: ") and "Traceback" not in err, err
    for word in words:
        assert word in err, err
    return err


def commands(w: dict, target: Path) -> dict:
    """Every writing command, writing to ``target`` (a path through a regular file, or in a read-only folder)."""
    d = str(w["data"])
    return {
        "export": (["export", str(w["ckpt"]), "-o", str(target / "m.fmu")], target / "m.fmu"),
        "linear -o": (["linear", "--data", d, "--order", "2", "--no-refine", "-o", str(target / "l.fmu")],
                      target / "l.fmu"),
        "linear --save": (["linear", "--data", d, "--order", "2", "--no-refine", "--save", str(target / "l.json")],
                          target / "l.json"),
        "physics-fmu": (["physics-fmu", "valve", "-o", str(target / "p.fmu")], target / "p.fmu"),
        "evaluate --json": (["evaluate", "--data", d, str(w["fmu"]), "--json", str(target / "s.json")],
                            target / "s.json"),
        "evaluate --plots": (["evaluate", "--data", d, str(w["fmu"]), "--plots", str(target / "figs")],
                             target / "figs"),
        "train": (["train", "--data", d, *TRAIN, "--out", str(target / "m.pt")], target / "m.pt"),
        "reproduce": (["reproduce", "valve", "--budget", "smoke", "--quiet", "--out", str(target / "study")],
                      target / "study"),
        "demo": (["demo", "--quiet", "--out", str(target / "demo")], target / "demo"),
        "generate": (["generate", "valve", "--size", "small", "--quiet", "--out", str(target / "d")], target / "d"),
    }


@pytest.mark.parametrize("name", ["export", "linear -o", "linear --save", "physics-fmu", "evaluate --json",
                                  "evaluate --plots", "train", "reproduce", "demo", "generate"])
def test_a_path_through_a_regular_file_is_one_line_and_status_2(work, capsys, name):
    argv, out = commands(work, work["afile"])[name]
    assert nnfmu_main(argv) == 2
    assert_one_line_error(capsys, f"nnfmu {argv[0]}", str(work["afile"]))
    assert work["afile"].read_text().startswith("a regular file")
    assert sorted(p.name for p in work["root"].iterdir()) == ["afile", "data", "gru.pt", "lin.fmu"]


WRITERS = ["export", "linear -o", "linear --save", "physics-fmu", "evaluate --json", "evaluate --plots", "train",
           "reproduce", "demo", "generate"]


@pytest.mark.parametrize("name", WRITERS)
def test_an_output_that_is_a_fifo_is_refused_and_left_a_fifo(work, tmp_path, capsys, name):
    """A FIFO (or a device node: tests/test_cli_nothing_lost.py) at an output is never replaced by a file."""
    argv, out = commands(work, tmp_path)[name]
    os.mkfifo(out)
    assert nnfmu_main(argv) == 2
    assert_one_line_error(capsys, f"nnfmu {argv[0]}", str(out))
    assert stat.S_ISFIFO(os.lstat(out).st_mode) and sorted(tmp_path.iterdir()) == [out]


@pytest.mark.parametrize("name", [w for w in WRITERS if w not in ("reproduce", "demo")])  # those: whole studies
def test_an_output_that_is_a_symlink_is_written_to_its_target_or_refused(work, tmp_path, capsys, name):
    """Either the link's target holds the result, or the command exits 2 with one line; the link stays a link."""
    argv, out = commands(work, tmp_path)[name]
    target = tmp_path / "real" / out.name
    target.parent.mkdir()
    out.symlink_to(target)
    status = nnfmu_main(argv)
    assert out.is_symlink() and os.readlink(out) == str(target)
    if status == 0:
        assert target.exists()
    else:
        assert status == 2 and "\n" not in capsys.readouterr().err.strip()


def test_python_m_nnfmu_export_keeps_the_contract(work, capsys):
    assert export_main([str(work["ckpt"]), "-o", str(work["afile"] / "m.fmu")]) == 2
    assert_one_line_error(capsys, "python -m nnfmu.export", "afile", "is a file, not a folder")


@pytest.fixture
def read_only_folder(tmp_path):
    """A folder nobody may create files in: a chmod 555 folder, or for root (who ignores permission bits)
    sysfs, which refuses new files even to root."""
    if os.geteuid() != 0:
        ro = tmp_path / "ro"
        ro.mkdir()
        ro.chmod(0o555)
        yield ro
        ro.chmod(0o755)
    else:
        yield Path("/sys")


@pytest.mark.parametrize("name", ["export", "linear -o", "linear --save", "evaluate --json", "train", "reproduce"])
def test_a_read_only_folder_is_one_line_and_status_2(work, capsys, read_only_folder, name):
    argv, out = commands(work, read_only_folder)[name]
    assert nnfmu_main(argv) == 2
    assert_one_line_error(capsys, f"nnfmu {argv[0]}", str(read_only_folder), "choose a location you may write to")
    assert not out.exists() and not list(read_only_folder.glob(".*.tmp"))


@contextlib.contextmanager
def file_size_limit(n_bytes: int):
    """Writes beyond ``n_bytes`` fail with EFBIG, as on a full disk (Python ignores SIGXFSZ)."""
    soft, hard = resource.getrlimit(resource.RLIMIT_FSIZE)
    resource.setrlimit(resource.RLIMIT_FSIZE, (n_bytes, hard))
    try:
        yield
    finally:
        resource.setrlimit(resource.RLIMIT_FSIZE, (soft, hard))


def test_a_full_disk_during_training_is_one_line_and_status_2(work, tmp_path, capsys):
    """torch's own writer used to end in 'RuntimeError: [enforce fail at inline_container.cc] unexpected pos'."""
    out = tmp_path / "m.pt"
    with file_size_limit(2000):
        status = nnfmu_main(["train", "--data", str(work["data"]), *TRAIN, "--out", str(out)])
    assert status == 2
    assert_one_line_error(capsys, "nnfmu train", f"cannot write {out}: File too large")
    assert list(tmp_path.iterdir()) == []


def test_a_failed_train_leaves_no_checkpoint_and_can_be_rerun(work, tmp_path, capsys):
    out = tmp_path / "m.pt"
    argv = ["train", "--data", str(work["data"]), *TRAIN, "--out", str(out)]
    assert nnfmu_main(argv + ["--truncate", "5000"]) == 2
    assert_one_line_error(capsys, "nnfmu train", "no training trajectory has 5000 samples")
    assert list(tmp_path.iterdir()) == []
    assert nnfmu_main(argv) == 0  # no 'exists; pass --resume'
    assert out.is_file()


@pytest.mark.parametrize("argv, words", [
    (["--hidden", "100000"], ["30,001,700,002 parameters", "limit of 50,000,000", "nnfmu.limits.MAX_PARAMETERS"]),
    (["--hidden", "2000", "--layers", "8"], ["parameters", "choose a smaller --hidden or --layers"]),
    (["--batch-size", "10000000"], ["--batch-size 10000000 is above nnfmu's limit of 100,000"]),
])
def test_sizes_are_checked_before_anything_is_allocated(work, tmp_path, capsys, argv, words):
    assert nnfmu_main(["train", "--data", str(work["data"]), "--arch", "gru", "--quiet", *argv,
                       "--out", str(tmp_path / "m.pt")]) == 2
    assert_one_line_error(capsys, "nnfmu train", *words)
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("argv, words", [
    (["linear", "--data", "D", "--max-order", "100000", "--save", "m.json"], ["--max-order 100000", "200"]),
    (["physics-fmu", "valve", "--n-sub", "10000000", "-o", "p.fmu"], ["--n-sub 10000000", "10,000"]),
])
def test_other_sizes_are_checked_too(work, tmp_path, capsys, argv, words):
    argv = [str(work["data"]) if a == "D" else str(tmp_path / a) if a.endswith((".json", ".fmu")) else a
            for a in argv]
    assert nnfmu_main(argv) == 2
    assert_one_line_error(capsys, f"nnfmu {argv[0]}", *words)


def _terminate_after_second_write(path: Path) -> threading.Thread:
    """SIGTERM to this process (from another thread) once ``path`` was written twice: epoch 0, then epoch 1."""
    def send():
        deadline, seen = time.monotonic() + 240, set()
        while len(seen) < 2 and time.monotonic() < deadline:
            with contextlib.suppress(OSError):
                info = path.stat()
                seen.add((info.st_ino, info.st_mtime_ns))
            time.sleep(0.01)
        os.kill(os.getpid(), signal.SIGTERM)

    thread = threading.Thread(target=send, daemon=True)
    thread.start()
    return thread


def test_sigterm_exits_with_143_and_keeps_the_checkpoint(work, tmp_path, capsys):
    out = tmp_path / "m.pt"
    previous = signal.signal(signal.SIGTERM, lambda *_: None)  # what the command restores; never kills pytest
    try:
        sender = _terminate_after_second_write(out)
        status = nnfmu_main(["train", "--data", str(work["data"]), "--arch", "gru", "--hidden", "4",
                             "--epochs", "100000", "--patience", "0", "--quiet", "--out", str(out)])
        sender.join()
    finally:
        signal.signal(signal.SIGTERM, previous)
    assert status == 143
    assert f"continue with --resume --out {out}" in capsys.readouterr().out
    assert out.is_file() and not list(tmp_path.glob(".*.tmp"))


def _sigterm(*args):
    os.kill(os.getpid(), signal.SIGTERM)


def test_sigterm_outside_training_also_exits_with_143(work, tmp_path, capsys):
    """Before training starts, SIGTERM ends the command like Ctrl-C: clean-up runs, nothing is left."""
    import nnfmu.cli._train_plan as train_plan

    out = tmp_path / "m.pt"
    previous = signal.signal(signal.SIGTERM, lambda *_: None)
    try:
        with mock.patch.object(train_plan, "_model_config", side_effect=_sigterm):
            status = nnfmu_main(["train", "--data", str(work["data"]), *TRAIN, "--out", str(out)])
    finally:
        signal.signal(signal.SIGTERM, previous)
    assert status == 143 and "terminated (SIGTERM)" in capsys.readouterr().err
    assert list(tmp_path.iterdir()) == []


def test_a_temporary_file_left_by_a_killed_writer_is_removed_by_the_next_write(tmp_path):
    target = tmp_path / "model.pt"
    writer = subprocess.Popen([sys.executable, "-c", (
        "import sys, time\nfrom nnfmu.atomic import write_atomic\n"
        "write_atomic(sys.argv[1], lambda tmp: (tmp.write_bytes(b'partial'), time.sleep(120)))"), str(target)])
    try:
        deadline = time.monotonic() + 60
        while not list(tmp_path.glob(".model.pt.*.tmp")) and time.monotonic() < deadline:
            time.sleep(0.05)
        (stale,) = tmp_path.glob(".model.pt.*.tmp")
    finally:
        writer.kill()  # SIGKILL: no clean-up can run
        writer.wait()
    assert stale.exists()
    legacy = tmp_path / ".model.pt.ab_cd123.tmp"  # the naming of earlier nnfmu versions (no pid): removed when old
    legacy.write_bytes(b"")
    os.utime(legacy, (time.time() - 7200, time.time() - 7200))
    other = tmp_path / ".other.pt.1.abcdef12.tmp"  # another target's: not ours to touch
    other.write_bytes(b"")
    write_atomic(target, lambda tmp: tmp.write_bytes(b"complete"))
    assert sorted(p.name for p in tmp_path.iterdir()) == [".other.pt.1.abcdef12.tmp", "model.pt"]
    assert target.read_bytes() == b"complete"


def test_written_files_get_the_usual_permissions(work, tmp_path):
    umask = os.umask(0)
    os.umask(umask)
    path = write_atomic(tmp_path / "f.json", lambda tmp: tmp.write_text("{}"))
    assert stat.S_IMODE(path.stat().st_mode) == 0o666 & ~umask
    path.chmod(0o600)  # an existing file keeps its own
    write_atomic(path, lambda tmp: tmp.write_text("[]"))
    assert stat.S_IMODE(path.stat().st_mode) == 0o600


class _RunsCode:
    def __init__(self, marker: Path):
        self.marker = marker

    def __reduce__(self):
        return (os.system, (f"touch {self.marker}",))


def test_a_hostile_checkpoint_is_refused_without_advice_to_unpickle_it(tmp_path, capsys):
    marker = tmp_path / "code-ran"
    torch.save({"format": "nnfmu-checkpoint", "payload": _RunsCode(marker)}, tmp_path / "evil.pt")
    assert export_main([str(tmp_path / "evil.pt"), "-o", str(tmp_path / "m.fmu")]) == 2
    err = assert_one_line_error(capsys, "python -m nnfmu.export", "is not a plain nnfmu checkpoint",
                                "GLOBAL posix.system", "Do not load it with weights_only=False")
    assert "will likely succeed" not in err and "Re-running" not in err
    assert not marker.exists() and not (tmp_path / "m.fmu").exists()
