"""Writing a dataset folder from `nnfmu import` and `nnfmu generate`: a full disk says what to do, and the
temporary folders of a killed run are removed by the next one (issue 24, items 7 and 8)."""

import errno
import os
import subprocess
import time

import numpy as np
import pytest

from nnfmu.cli import main
from nnfmu.data import from_arrays, load_dataset, save_dataset
from nnfmu.errors import DataFileError


def _tiny():
    rng = np.random.default_rng(0)
    u, y = rng.normal(size=(3, 20, 1)), rng.normal(size=(3, 20, 1))
    return from_arrays(Ts=0.1, u_train=u[:2], y_train=y[:2], u_test=u[2:], y_test=y[2:],
                       source={"system": "valve"})


def _dead_pid() -> int:
    child = subprocess.Popen(["true"])
    child.wait()  # reaped: its pid names no process
    return child.pid


def test_a_later_save_removes_the_temporary_folders_of_killed_saves_only(tmp_path):
    def temp(name, age_s=0.0):
        folder = tmp_path / name
        folder.mkdir()
        (folder / "train.npz").write_bytes(b"half written")
        if age_s:
            os.utime(folder, (time.time() - age_s, time.time() - age_s))
        return folder

    dead = temp(f".d.{_dead_pid()}.abc_e7gh.tmp")           # its process was killed
    running = temp(f".d.{os.getpid()}.k2mnopqr.tmp")        # a save still running
    old = temp(".d.a1b2c3d4.tmp", age_s=2 * 3600)           # the naming before the pid, abandoned long ago
    recent = temp(".d.z9y8x7w6.tmp")                        # the same naming, maybe still being written
    other = temp(f".other.{_dead_pid()}.abcdefgh.tmp")      # another target's
    save_dataset(_tiny(), tmp_path / "d")
    assert not dead.exists() and not old.exists()
    assert running.exists() and recent.exists() and other.exists()
    assert sorted(p.name for p in tmp_path.iterdir() if p.name.endswith(".tmp")) == sorted(
        [running.name, recent.name, other.name])


def _full_disk(file, tr):
    raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))


def test_a_full_disk_in_import_says_what_to_do_and_leaves_nothing(tmp_path, capsys, monkeypatch):
    import nnfmu.data.storage as storage

    (tmp_path / "a.csv").write_text("u,y\n" + "".join(f"{i},{i * i}\n" for i in range(10)))
    monkeypatch.setattr(storage, "_write_split", _full_disk)
    out = tmp_path / "D"
    assert main(["import", "csv", str(tmp_path / "a.csv"), "--inputs", "u", "--outputs", "y", "--Ts", "1",
                 "--test-columns", "y,u", "-o", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "[Errno" not in err, err
    assert f"no space left on device at {out}; free space or choose another folder (CLI: another -o)" in err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.csv"]


def test_a_full_disk_in_generate_says_what_to_do_and_leaves_nothing(tmp_path, capsys, monkeypatch):
    import nnfmu.data.storage as storage
    import nnfmu.physics

    monkeypatch.setattr(nnfmu.physics, "generate_dataset", lambda *a, **k: _tiny())
    monkeypatch.setattr(storage, "_write_split", _full_disk)
    assert main(["generate", "valve", "--size", "small", "--quiet", "-o", str(tmp_path / "G")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "no space left on device at" in err and "[Errno" not in err, err
    assert list(tmp_path.iterdir()) == []
    with pytest.raises(DataFileError, match="no space left on device"):
        save_dataset(_tiny(), tmp_path / "P")


def test_an_imported_dataset_is_named_after_its_folder(tmp_path):
    (tmp_path / "tanks_run1.csv").write_text("u,y\n" + "".join(f"{i},{i * i}\n" for i in range(10)))
    assert main(["import", "csv", str(tmp_path / "tanks_run1.csv"), "--inputs", "u", "--outputs", "y", "--Ts",
                 "1", "--test-columns", "y,u", "-o", str(tmp_path / "2tanks-data")]) == 0
    assert load_dataset(tmp_path / "2tanks-data").source["name"] == "d_2tanks_data"  # an identifier


@pytest.mark.parametrize("umask, mode", [(0o022, 0o755), (0o027, 0o750)])
def test_a_dataset_folder_follows_the_umask(tmp_path, umask, mode):
    """Issue 37, item 8: the folder was created 0700 (tempfile.mkdtemp) whatever the umask, so nobody else could
    read a dataset shared on a group folder."""
    old = os.umask(umask)
    try:
        save_dataset(_tiny(), tmp_path / "d")
    finally:
        os.umask(old)
    assert (tmp_path / "d").stat().st_mode & 0o777 == mode
    assert (tmp_path / "d" / "meta.json").stat().st_mode & 0o777 == mode & 0o666
