"""Issue 24, items 5-8 and 15: the exact calls that ended in a traceback, were accepted although invalid, left
files behind or printed an unhelpful message; each now gives one line naming the argument and exit status 2."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
import warnings
from pathlib import Path

import numpy as np
import pytest
import torch
from fmu_cases import oscillator_dataset
from test_cli_contract import file_size_limit

from nnfmu.cli import build_parser, command_parser, run
from nnfmu.cli import main as nnfmu_main
from nnfmu.data import from_arrays, save_dataset
from nnfmu.errors import ConfigError
from nnfmu.models import ModelConfig, build_model, save_checkpoint

pytestmark = pytest.mark.usefixtures("one_thread")
TRAIN = ["--arch", "gru", "--hidden", "4", "--epochs", "1", "--batch-size", "4", "--quiet"]
META = {"name": "osc_gru", "Ts": 0.01, "inputs": [{"name": "force", "unit": "N"}],
        "outputs": [{"name": "pos", "unit": "m"}, {"name": "vel", "unit": "m/s"}]}


@pytest.fixture(scope="module")
def work(tmp_path_factory):
    """A tiny oscillator dataset (3 train, 1 test trajectory of 60 samples), its linear FMU, constant data."""
    root = tmp_path_factory.mktemp("messages")
    data = oscillator_dataset(root / "data")
    ones = [np.ones((60, 1))] * 4
    constant = save_dataset(from_arrays(Ts=0.01, u_train=ones[:3], y_train=ones[:3], u_test=ones[3:],
                                        y_test=ones[3:]), root / "constant")
    assert nnfmu_main(["linear", "--data", str(data), "--order", "2", "--no-refine", "-o", str(root / "lin.fmu")]) == 0
    return {"root": root, "data": str(data), "constant": str(constant), "fmu": str(root / "lin.fmu")}


def one_line(capsys, *words: str) -> str:
    """stderr's last line (progress bars before it are redrawn lines) is the one error line with ``words``."""
    err = capsys.readouterr().err
    assert "Traceback" not in err and "Warning" not in err, err
    line = err.replace("\r", "\n").strip().splitlines()[-1]
    assert ": error: " in line, err
    for word in words:
        assert word in line, line
    return line


def test_linear_on_constant_data(work, tmp_path, capsys):
    assert nnfmu_main(["linear", "--data", work["constant"], "--max-order", "2", "--quiet",
                       "--save", str(tmp_path / "l.json")]) == 2
    one_line(capsys, "no dynamics", "constant")
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("argv, words", [
    (["--trajectory", "999"], ["--trajectory 999 is out of range", "1 trajectories in the test split"]),
    (["--trajectory", "-1"], ["--trajectory must be a whole number >= 0, got -1"]),
    (["--init-window", "-1"], ["--init-window must be a whole number >= 1, got -1"]),
    (["--init-window", "60"], ["--init-window 60 leaves nothing to run on", "choose --init-window below 60"]),
])
def test_evaluate_refuses_a_bad_trajectory_or_window_before_simulating(work, tmp_path, capsys, argv, words):
    assert nnfmu_main(["evaluate", "--data", work["data"], work["fmu"], "--plots", str(tmp_path / "P"),
                       *argv]) == 2
    one_line(capsys, *words)
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("argv, words", [
    (["--init-window", "100000"], ["--init-window 100000 leaves nothing to run on", "has 60 samples"]),
    (["--max-minutes", "1e308"], ["--max-minutes 1e+308 is above nnfmu's limit", "MAX_MINUTES"]),
    (["--seed", "-5"], ["--seed must be a whole number >= 0", "got -5"]),
    (["--seeds", "100000"], ["--seeds 100000 is above nnfmu's limit of 100", "ensemble of 5 to 10"]),
    (["--lr", "nan"], ["--lr must be a finite number > 0"]),
])
def test_train_refuses_hostile_numbers_before_training(work, tmp_path, capsys, argv, words):
    assert nnfmu_main(["train", "--data", work["data"], *TRAIN, *argv, "-o", str(tmp_path / "m.pt")]) == 2
    one_line(capsys, *words)
    assert list(tmp_path.iterdir()) == []


def test_evaluate_on_a_full_disk_leaves_no_scores(work, tmp_path, capsys):
    out = tmp_path / "DIR"
    with file_size_limit(4000):  # scores.json fits, the PNG does not
        assert nnfmu_main(["evaluate", "--data", work["data"], work["fmu"], "-o", str(out)]) == 2
    one_line(capsys, "File too large")
    assert list(tmp_path.iterdir()) == []


def test_linear_with_an_unwritable_save_writes_no_fmu(work, tmp_path, capsys):
    ro = Path("/sys") if os.geteuid() == 0 else tmp_path / "ro"
    if ro != Path("/sys"):
        ro.mkdir()
        ro.chmod(0o555)
    try:
        assert nnfmu_main(["linear", "--data", work["data"], "--order", "2", "--no-refine", "--quiet",
                           "-o", str(tmp_path / "l.fmu"), "--save", str(ro / "l.json")]) == 2
    finally:
        if ro != Path("/sys"):
            ro.chmod(0o755)
    one_line(capsys, str(ro / "l.json"), "choose a location you may write to")
    assert not (tmp_path / "l.fmu").exists()


def test_a_killed_exports_build_folder_is_removed_by_the_next_export(work, tmp_path, capsys):
    dead = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True, text=True)
    pid = int(dead.stdout)  # exited and reaped: no process has this pid (unless the system reuses it at once)
    stale = Path(tempfile.gettempdir()) / f"nnfmu-build-{pid}-abcd1234"
    live = Path(tempfile.gettempdir()) / f"nnfmu-build-{os.getppid()}-abcd1234"  # a running process's
    for folder in (stale, live):
        (folder / "fmu").mkdir(parents=True)
    try:
        assert nnfmu_main(["physics-fmu", "valve", "--fixed-parameters", "--no-model-exchange",
                           "-o", str(tmp_path / "v.fmu")]) == 0
        assert not stale.exists() and live.is_dir()
        assert not list(Path(tempfile.gettempdir()).glob(f"nnfmu-build-{os.getpid()}-*"))  # its own is gone too
    finally:
        for folder in (stale, live):
            subprocess.run(["rm", "-rf", str(folder)], check=False)


def test_a_bogus_target_isa_is_one_line_with_the_choices(work, tmp_path, capsys):
    assert nnfmu_main(["physics-fmu", "valve", "--target-isa", "bogus", "-o", str(tmp_path / "v.fmu")]) == 2
    line = one_line(capsys, "--target-isa 'bogus'", "choose one of: native")
    assert "compiler stderr" not in line and list(tmp_path.iterdir()) == []


def test_a_checkpoint_with_nan_weights_is_blamed_on_the_training(tmp_path, capsys):
    net = build_model(ModelConfig(arch="gru", n_u=1, n_y=2, hidden=4), META)
    with torch.no_grad():
        next(net.parameters()).fill_(float("nan"))
    ckpt = save_checkpoint(tmp_path / "nan.pt", net)
    assert nnfmu_main(["export", str(ckpt), "-o", str(tmp_path / "nan.fmu")]) == 2
    line = one_line(capsys, "weights are not finite", "diverged", "lower learning rate")
    assert "overridden method" not in line and not (tmp_path / "nan.fmu").exists()


def test_warnings_are_dropped_when_the_command_fails_and_shown_when_it_succeeds(capsys):
    def failing(args):
        warnings.warn("numpy said something", RuntimeWarning)
        raise ConfigError("--x must be 1")

    def working(args):
        warnings.warn("torch said something", UserWarning)
        return 0

    with warnings.catch_warnings(record=True) as shown:  # what would reach stderr before the error line
        warnings.simplefilter("always")
        assert run(failing, None, "nnfmu x") == 2
    assert shown == [] and capsys.readouterr().err == "nnfmu x: error: --x must be 1\n"
    with warnings.catch_warnings(record=True) as shown:
        warnings.simplefilter("always")
        assert run(working, None, "nnfmu x") == 0
    assert [str(w.message) for w in shown] == ["torch said something"]


def test_help_is_readable():
    text = build_parser().format_help()
    assert "fit %, R2, RMSE and MAE" in text and "option_strings" not in text
    evaluate = command_parser(build_parser(), "evaluate").format_help()
    assert "fit % = 100 (1 - NRMSE)" in " ".join(evaluate.split())
    sub = next(a for a in build_parser()._actions if a.dest == "command")
    for name, parser in sub.choices.items():  # every command's help: no escaped or garbled percent signs
        text = parser.format_help()
        assert "%%" not in text and "option_strings" not in text, name


def test_evaluate_prints_r2_and_mae_and_out_of_range_only_when_there_is_some(work, tmp_path, capsys):
    assert nnfmu_main(["evaluate", "--data", work["data"], work["fmu"], "--split", "train",
                       "--json", str(tmp_path / "s.json")]) == 0
    text = capsys.readouterr().out
    assert "R2" in text and "MAE pos [m]" in text and "outside the valid range" not in text  # train: inside
    model = json.loads((tmp_path / "s.json").read_text())["models"][0]
    assert model["r2"] == pytest.approx(1.0) and model["outputs"]["pos"]["mae"] < 1e-12
    assert nnfmu_main(["evaluate", "--data", work["data"], work["fmu"]]) == 0
    assert "inputs outside the valid range of lin: 2 of 60 samples" in capsys.readouterr().out  # test: 2 outside
