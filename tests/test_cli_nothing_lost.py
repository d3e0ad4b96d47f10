"""Nothing that nnfmu did not write is ever lost: ``--force`` replaces only nnfmu's own folders and files, and an
output path that is a device node, a FIFO or a socket is refused, while a symbolic link is written through."""

from __future__ import annotations

import os
import socket
import stat
from pathlib import Path

import pytest
from fmu_cases import oscillator_dataset

from nnfmu.cli import main as nnfmu_main

pytestmark = pytest.mark.usefixtures("one_thread")


@pytest.fixture(scope="module")
def work(tmp_path_factory):
    root = tmp_path_factory.mktemp("lost")
    data = oscillator_dataset(root / "data")
    fmu = root / "lin.fmu"
    assert nnfmu_main(["linear", "--data", str(data), "--order", "2", "--no-refine", "--quiet", "-o", str(fmu)]) == 0
    csv = root / "d.csv"
    csv.write_text("u,y\n" + "".join(f"{k % 7 - 3},{k % 5}\n" for k in range(60)))
    csv2 = root / "d2.csv"
    csv2.write_text(csv.read_text())
    return {"data": str(data), "fmu": str(fmu), "csv": str(csv), "csv2": str(csv2)}


def one_line_error(capsys, *words: str) -> str:
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and ": error: " in err and "Traceback" not in err, err
    for word in words:
        assert word in err, err
    return err


def _user_folder(path: Path) -> Path:
    path.mkdir()
    (path / "keep.txt").write_text("a thesis")
    (path / "chapter").mkdir()
    (path / "chapter" / "one.txt").write_text("chapter one")
    return path


FORCE = {
    "generate": lambda w, out: ["generate", "slider", "--size", "small", "--quiet", "-o", str(out), "--force"],
    "import": lambda w, out: ["import", "csv", w["csv"], "--inputs", "u", "--outputs", "y", "--Ts", "0.01",
                              "--test", w["csv2"], "-o", str(out), "--force"],
}


@pytest.mark.parametrize("command", sorted(FORCE))
def test_force_never_replaces_a_folder_of_other_files(work, tmp_path, capsys, command):
    out = _user_folder(tmp_path / "P")
    assert nnfmu_main(FORCE[command](work, out)) == 2
    one_line_error(capsys, str(out), "keep.txt", "not a dataset folder")
    assert (out / "keep.txt").read_text() == "a thesis"
    assert (out / "chapter" / "one.txt").read_text() == "chapter one"


def test_force_replaces_a_dataset_folder_and_an_empty_one(work, tmp_path, capsys):
    out = tmp_path / "D"
    assert nnfmu_main(FORCE["import"](work, out)) == 0
    (out / "valid.npz").unlink(missing_ok=True)
    assert nnfmu_main(FORCE["import"](work, out)) == 0  # a dataset folder nnfmu wrote is replaced
    assert sorted(p.name for p in out.iterdir()) == ["meta.json", "test.npz", "train.npz"]
    empty = tmp_path / "E"
    empty.mkdir()
    assert nnfmu_main(FORCE["import"](work, empty)) == 0
    assert (empty / "meta.json").is_file()


def test_train_force_never_overwrites_a_file_that_is_not_a_checkpoint(work, tmp_path, capsys):
    out = tmp_path / "notes.pt"
    out.write_text("my notes")
    argv = ["train", "--data", work["data"], "--arch", "gru", "--hidden", "4", "--epochs", "1", "--quiet",
            "--out", str(out), "--force"]
    assert nnfmu_main(argv) == 2
    one_line_error(capsys, str(out), "not an nnfmu checkpoint")
    assert out.read_text() == "my notes"


def _node(kind: str, path: Path) -> Path:
    if kind == "character device":
        if os.geteuid() != 0:
            pytest.skip("creating a character device (mknod) needs root")
        os.mknod(path, stat.S_IFCHR | 0o666, os.makedev(1, 7))  # the numbers of /dev/full, in our own folder
    elif kind == "FIFO":
        os.mkfifo(path)
    else:
        sock = socket.socket(socket.AF_UNIX)
        sock.bind(str(path))
        sock.close()
    return path


WRITES = {
    "evaluate --json": lambda w, out: ["evaluate", "--data", w["data"], w["fmu"], "--json", str(out)],
    "linear --save": lambda w, out: ["linear", "--data", w["data"], "--order", "2", "--no-refine", "--quiet",
                                     "--save", str(out)],
}


@pytest.mark.parametrize("kind", ["character device", "FIFO", "socket"])
@pytest.mark.parametrize("command", sorted(WRITES))
def test_a_device_fifo_or_socket_output_is_refused_and_left_as_it_was(work, tmp_path, capsys, command, kind):
    node = _node(kind, tmp_path / "node")
    before = os.lstat(node)
    assert nnfmu_main(WRITES[command](work, node)) == 2
    one_line_error(capsys, str(node), kind, "not a regular file")
    after = os.lstat(node)
    assert stat.S_IFMT(after.st_mode) == stat.S_IFMT(before.st_mode) and after.st_rdev == before.st_rdev


@pytest.mark.parametrize("command", sorted(WRITES))
def test_a_symlink_output_is_written_through_to_its_target(work, tmp_path, capsys, command):
    target = tmp_path / "real.json"
    target.write_text("old")
    link = tmp_path / "link.json"
    link.symlink_to(target)
    dangling = tmp_path / "dangling.json"
    dangling.symlink_to(tmp_path / "new.json")
    for out, result in ((link, target), (dangling, tmp_path / "new.json")):
        assert nnfmu_main(WRITES[command](work, out)) == 0
        assert out.is_symlink() and os.readlink(out) == str(result)
        assert result.read_text().lstrip().startswith("{")


def test_a_symlink_to_a_device_is_refused(work, tmp_path, capsys):
    node = _node("FIFO", tmp_path / "fifo")
    link = tmp_path / "out.json"
    link.symlink_to(node)
    assert nnfmu_main(WRITES["linear --save"](work, link)) == 2
    one_line_error(capsys, str(node), "FIFO")
    assert link.is_symlink() and stat.S_ISFIFO(os.stat(link).st_mode)
