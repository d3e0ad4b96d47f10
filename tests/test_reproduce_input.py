"""`nnfmu reproduce` says what is wrong with its input before it touches the study folder."""

import shutil

import pytest

from nnfmu.cli import main

pytestmark = pytest.mark.usefixtures("one_thread")


def _reproduce(capsys, *args) -> tuple[int, str]:
    code = main(["reproduce", *map(str, args), "--budget", "smoke", "--quiet"])
    return code, capsys.readouterr().err


def test_missing_and_wrong_data_leave_the_folder_as_it_was(tmp_path, capsys):
    out = tmp_path / "study"
    code, err = _reproduce(capsys, "robot", "-o", out)
    assert code == 2 and "robot study needs measured data: pass --data" in err and not out.exists()
    code, err = _reproduce(capsys, "robot", "-o", out, "--data", tmp_path / "nowhere.mat")
    assert code == 2 and "nowhere.mat not found" in err and not out.exists()
    out.mkdir()
    (out / "notes.txt").write_text("mine")
    code, err = _reproduce(capsys, "robot", "-o", out, "--data", tmp_path / "nowhere.mat")
    assert code == 2 and "not found" in err and [p.name for p in out.iterdir()] == ["notes.txt"]


def test_data_of_another_system_are_refused(valve_small_dir, tmp_path, capsys):
    code, err = _reproduce(capsys, "robot", "-o", tmp_path / "r", "--data", valve_small_dir)
    assert code == 2 and "holds valve data, not robot data" in err and not (tmp_path / "r").exists()
    code, err = _reproduce(capsys, "arm", "-o", tmp_path / "a", "--data", valve_small_dir)
    assert code == 2 and "holds valve data, not arm data" in err and not (tmp_path / "a").exists()


def test_data_without_a_test_split_leave_no_study_behind(valve_small_dir, tmp_path, capsys):
    data = tmp_path / "no-test"
    shutil.copytree(valve_small_dir, data)
    (data / "test.npz").unlink()
    code, err = _reproduce(capsys, "valve", "-o", tmp_path / "s", "--data", data)
    assert code == 2 and "has no 'test' split" in err and not (tmp_path / "s").exists()
