"""What every command shares: plain-text help, -o/--out where it writes, and `nnfmu info` on each kind of file."""

import argparse
import json
import re

import numpy as np
import pytest

from nnfmu.cli import build_parser, main
from nnfmu.data import Channel, from_arrays, save_dataset

WRITERS = {"demo", "evaluate", "export", "fit", "generate", "import", "linear", "physics-fmu", "reproduce", "train",
           "tune"}
REST = re.compile(r"``|:(mod|class|func|meth|data|attr):`")


def _commands() -> dict[str, argparse.ArgumentParser]:
    sub = next(a for a in build_parser()._actions if isinstance(a, argparse._SubParsersAction))
    return dict(sub.choices)


def test_help_texts_are_plain_text():
    for name, parser in _commands().items():
        text = parser.format_help()
        assert not REST.search(text), (name, REST.search(text).group(0))


def test_every_command_that_writes_takes_dash_o():
    commands = _commands()
    assert WRITERS <= set(commands)
    for name, parser in commands.items():
        flags = {s for a in parser._actions for s in a.option_strings}
        if name in WRITERS:
            assert {"-o", "--out"} <= flags, name
        else:
            assert "--out" not in flags, name


@pytest.fixture(scope="module")
def dataset_dir(tmp_path_factory):
    rng = np.random.default_rng(0)
    u, y = rng.normal(size=(60, 1)), np.cumsum(rng.normal(size=(60, 1)), axis=0)
    ds = from_arrays(Ts=0.5, u_train=u, y_train=y, u_test=u[:30], y_test=y[:30] + 1,
                     input_names=[Channel("force", "N")], output_names=[Channel("pos", "m")])
    return save_dataset(ds.replace(init_window=5), tmp_path_factory.mktemp("info") / "data")


def test_info_on_a_dataset(dataset_dir, capsys):
    assert main(["info", str(dataset_dir)]) == 0
    text = capsys.readouterr().out
    assert "dataset" in text and "Ts: 0.5" in text and "force [N]" in text and "pos [m]  range" in text
    assert main(["info", str(dataset_dir), "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["init_window"] == 5 and doc["splits"]["test"]["n_samples"] == 30
    assert doc["outputs"][0]["range"][1] == pytest.approx(float(max(doc["outputs"][0]["range"])))


def test_info_on_an_fmu_and_a_checkpoint(dataset_dir, tmp_path, capsys):
    import nnfmu
    from nnfmu.export import build_fmu, casadi_model

    ds = nnfmu.load_dataset(dataset_dir)
    result = nnfmu.train(ds, nnfmu.ModelConfig(arch="mlp", n_u=1, n_y=1, hidden=4),
                         nnfmu.TrainConfig(epochs=1, batch_size=4), out=tmp_path / "m.pt")
    assert main(["info", str(tmp_path / "m.pt"), "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["kind"] == "checkpoint" and doc["model_config"]["arch"] == "mlp" and doc["Ts"] == 0.5
    assert doc["outputs"][0]["name"] == "pos" and doc["outputs"][0]["unit"] == "m" and "mean" in doc["outputs"][0]
    assert doc["training"]["stop_reason"] == "epochs" and doc["training"]["best_epoch"] in (0, 1)
    build_fmu(casadi_model(result.model, name="info_mlp"), tmp_path / "m.fmu")
    assert main(["info", str(tmp_path / "m.fmu")]) == 0
    text = capsys.readouterr().out
    assert "model: info_mlp" in text and "fmi_version: 2.0" in text and "Ts: 0.5" in text
    assert "force [N]" in text and "pos [m]" in text and "pos_start [m]" in text and "linux64" in text
    assert main(["info", str(tmp_path / "none.fmu")]) == 2
    assert "none.fmu not found" in capsys.readouterr().err


def test_info_is_a_readable_summary_that_says_which_range(dataset_dir, capsys):
    assert main(["info", str(dataset_dir)]) == 0
    text = capsys.readouterr().out
    assert "ranges: in the train split (as 'nnfmu import' prints them), then over all splits" in text
    assert "train: 1 trajectories, 60 samples" in text and "{" not in text  # no raw JSON in the summary
    assert main(["info", str(dataset_dir), "--json"]) == 0
    force = json.loads(capsys.readouterr().out)["inputs"][0]
    assert force["train_range"][0] >= force["range"][0] and force["train_range"][1] <= force["range"][1]


def test_info_shows_a_time_budget_not_the_epoch_sentinel():
    from nnfmu.cli.info import render
    from nnfmu.limits import UNBOUNDED_EPOCHS

    text = render({"kind": "checkpoint", "path": "m.pt", "name": "m", "Ts": 0.1,
                   "train_config": {"epochs": UNBOUNDED_EPOCHS, "max_minutes": 2.0, "lr": 0.003},
                   "training": {"stop_reason": "time-budget", "seconds": 120.04, "resumable": True}})
    assert "epochs unbounded (time budget), max_minutes 2, lr 0.003" in text
    assert str(UNBOUNDED_EPOCHS) not in text and "seconds 120.0 s" in text and "resumable yes" in text
