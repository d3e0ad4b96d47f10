"""``nnfmu train``: every architecture and strategy writes a loadable checkpoint; bad input is one line."""

from __future__ import annotations

import dataclasses
import re
import subprocess
import sys

import numpy as np
import pytest
import torch

import nnfmu
from nnfmu.cli import main
from nnfmu.cli import train as cli
from nnfmu.data import Trajectories, save_dataset
from nnfmu.models import ModelConfig, load_checkpoint
from nnfmu.training import STRATEGIES, TrainConfig
from builtin_networks import ARCHS

QUICK = ["--epochs", "1", "--hidden", "8", "--truncate", "30", "--batch-size", "16", "--quiet"]


pytestmark = pytest.mark.usefixtures("one_thread")


@pytest.fixture(scope="module")
def data_dir(valve_small, tmp_path_factory):
    """A reduced valve dataset folder with its own valid split: 8 train, 2 valid, 1 test trajectory."""
    tr, te = valve_small.train, valve_small.test
    splits = {"train": tr.subset(range(8)), "valid": tr.subset([8, 9]),
              "test": Trajectories((te.u[0][:600],), (te.y[0][:600],))}
    return save_dataset(valve_small.replace(splits=splits), tmp_path_factory.mktemp("data") / "valve")


@pytest.mark.parametrize("arch", ARCHS)
@pytest.mark.parametrize("strategy", STRATEGIES)
def test_train_writes_a_checkpoint_that_loads_and_simulates(data_dir, tmp_path, capsys, arch, strategy):
    out = tmp_path / "model.pt"
    extra = ["--layers", "2"] if arch == "tcn" else []
    assert main(["train", "--data", str(data_dir), "--arch", arch, "--strategy", strategy, "--out", str(out),
                 *QUICK, *extra]) == 0
    printed = capsys.readouterr().out
    assert "test free-run NRMSE: " in printed and "(s " in printed
    raw = torch.load(out, weights_only=True)
    assert raw["model_config"]["arch"] == arch and raw["train_config"]["strategy"] == strategy
    ds = nnfmu.load_dataset(data_dir)
    u, y = ds.test.u[0], ds.test.y[0]
    sim = nnfmu.load_model(out).simulate(u, y[0])
    assert sim.shape == y.shape and np.isfinite(sim).all() and np.array_equal(sim[0], y[0])
    assert f"{raw['summary']['test_nrmse']:.4f}" in printed


def test_progress_bar_shows_loss_and_validation_nrmse(data_dir, tmp_path, capsys):
    out = tmp_path / "m.pt"
    assert main(["train", "--data", str(data_dir), "--arch", "mlp", "--out", str(out),
                 *[a for a in QUICK if a != "--quiet"], "--epochs", "2"]) == 0
    bar = capsys.readouterr().err
    assert "mlp parallel" in bar and "loss=" in bar and "valid=" in bar and "2/2" in bar


def test_resume_continues_from_the_checkpoint(data_dir, tmp_path, capsys):
    out = tmp_path / "m.pt"
    args = ["train", "--data", str(data_dir), "--out", str(out)]
    assert main([*args, "--arch", "gru", *QUICK]) == 0
    assert main([*args, "--resume", "--epochs", "2", "--quiet"]) == 0
    ckpt = load_checkpoint(out)
    assert ckpt["resume"]["epoch"] == 2 and ckpt["train_config"]["epochs"] == 2
    assert ckpt["model_config"]["hidden"] == 8  # the stored model, not the default width
    capsys.readouterr()
    assert main([*args, "--resume", "--hidden", "16", "--quiet"]) == 2
    assert "options {'hidden': 16} differ" in capsys.readouterr().err


@pytest.mark.parametrize("argv, message", [
    (["--arch", "gru"], "exists; pass --resume to continue it, --force to overwrite it"),
    (["--resume"], "not an nnfmu checkpoint"),
    (["--arch", "gru", "--force", "--window", "3"], "window must be 1"),
    (["--arch", "gru", "--force", "--epochs", "0"], "--epochs must be a whole number >= 1"),
])
def test_bad_options_give_one_line_errors(data_dir, tmp_path, capsys, argv, message):
    out = tmp_path / "exists.pt"
    torch.save({"a": 1}, out)
    assert main(["train", "--data", str(data_dir), "--out", str(out), *argv]) == 2
    err = capsys.readouterr().err
    assert err.startswith("nnfmu train: error: ") and message in err and len(err.strip().splitlines()) == 1


def test_nan_in_a_dataset_folder_is_a_clear_error(data_dir, tmp_path, capsys):
    bad = tmp_path / "bad"
    ds = nnfmu.load_dataset(data_dir)
    save_dataset(ds, bad)
    with np.load(bad / "train.npz") as f:
        arrays = dict(f)
    arrays["y"][0, 5, 1] = np.nan
    np.savez(bad / "train.npz", **arrays)
    assert main(["train", "--data", str(bad), "--arch", "mlp", "--out", str(tmp_path / "m.pt"), *QUICK]) == 2
    err = capsys.readouterr().err
    assert "non-finite" in err and "train" in err and not (tmp_path / "m.pt").exists()


def test_help_texts_state_the_real_defaults():
    mlp = ModelConfig(arch="mlp", n_u=1, n_y=1)  # the window help speaks of the MLP
    defaults = {**dataclasses.asdict(TrainConfig()), **dataclasses.asdict(mlp)}
    checked = 0
    for _, dest, _, text in cli._MODEL_OPTIONS + cli._TRAIN_OPTIONS:
        stated = re.search(r"\(default ([0-9.e-]+)\)", text)
        if stated:
            assert float(stated.group(1)) == defaults[dest], dest
            checked += 1
    assert checked >= 9


def test_the_installed_command_runs(data_dir, tmp_path):
    out = tmp_path / "m.pt"
    proc = subprocess.run([sys.executable, "-m", "nnfmu", "train", "--data", str(data_dir), "--arch", "rnn",
                           "--out", str(out), *QUICK], capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    assert "test free-run NRMSE" in proc.stdout and out.is_file()
