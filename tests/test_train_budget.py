"""`nnfmu train --max-minutes M` alone: train until the budget is spent, keep the best, show the time left."""

import re

import pytest

from nnfmu.cli import main
from nnfmu.data import Trajectories, save_dataset
from nnfmu.limits import UNBOUNDED_EPOCHS
from nnfmu.models import load_checkpoint

pytestmark = pytest.mark.usefixtures("one_thread")


@pytest.fixture(scope="module")
def data_dir(valve_small, tmp_path_factory):
    tr, te = valve_small.train, valve_small.test
    splits = {"train": tr.subset(range(4)), "valid": tr.subset([4]),
              "test": Trajectories((te.u[0][:300],), (te.y[0][:300],))}
    return save_dataset(valve_small.replace(splits=splits), tmp_path_factory.mktemp("budget") / "valve")


def test_max_minutes_alone_is_the_only_limit(data_dir, tmp_path, capsys, monkeypatch):
    """Where the search does not apply (the hybrid's record), --max-minutes alone trains one network until the
    budget is spent."""
    monkeypatch.setattr("nnfmu.cli._train_plan.search_applies", lambda args: False)
    out = tmp_path / "m.pt"
    assert main(["train", "--data", str(data_dir), "--arch", "mlp", "--hidden", "4", "--truncate", "30",
                 "--max-minutes", "0.03", "-o", str(out)]) == 0
    captured = capsys.readouterr()
    ckpt = load_checkpoint(out)
    assert ckpt["train_config"]["epochs"] == UNBOUNDED_EPOCHS and ckpt["train_config"]["patience"] == 0
    assert ckpt["summary"]["stop_reason"] == "time-budget"
    assert ckpt["best_epoch"] == min(range(len(ckpt["history"])), key=lambda e: ckpt["history"][e]["valid_nrmse"])
    assert "stopped: time-budget" in captured.out
    # the bar counts epochs in its description (in a log, as here, its first and last state: epoch 0, epoch N)
    assert "of 00:02 budget" in captured.err and re.search(r"epoch [1-9][0-9]* ", captured.err)


def test_bar_counts_epochs_when_epochs_bound_the_run_and_names_the_time_limit(data_dir, tmp_path, capsys):
    """The presets' wall clock is a safety net: the bar shows the epochs, and never more time left than the limit."""
    assert main(["train", "--data", str(data_dir), "--arch", "mlp", "--hidden", "4", "--truncate", "30",
                 "--max-minutes", "60", "--epochs", "3", "-o", str(tmp_path / "m.pt")]) == 0
    err = capsys.readouterr().err
    assert "mlp parallel (time limit 1:00:00)" in err and "3/3" in err
    assert "budget" not in err


def test_max_minutes_with_epochs_keeps_both_limits(data_dir, tmp_path):
    out = tmp_path / "m.pt"
    assert main(["train", "--data", str(data_dir), "--arch", "mlp", "--hidden", "4", "--truncate", "30",
                 "--max-minutes", "5", "--epochs", "2", "--quiet", "-o", str(out)]) == 0
    ckpt = load_checkpoint(out)
    cfg = ckpt["train_config"]
    assert cfg["epochs"] == 2 and cfg["max_minutes"] == 5 and cfg["patience"] > 0  # patience: the plan's, in steps
    assert ckpt["summary"]["stop_reason"] == "epochs"
