"""``nnfmu train --arch hybrid`` -> ``python -m nnfmu.export``: one FMU that fmpy validates and that equals torch."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest
from fmpy.validation import validate_fmu

from nnfmu.cli import main
from nnfmu.cosim import FmuSimulator
from nnfmu.data import Trajectories, save_dataset
from nnfmu.hybrid import HybridStepModel
from nnfmu.models import load_checkpoint, load_model

WRONG_VALVE = {"k_s": 32500.0, "C_max": 4.2e-10, "d_c": 0.0}


pytestmark = pytest.mark.usefixtures("one_thread")


@pytest.fixture(scope="module")
def folders(valve_small, tmp_path_factory):
    """A reduced valve dataset (6 train, 2 valid, 1 test trajectory) and a wrong-parameter file."""
    root = tmp_path_factory.mktemp("hybrid_cli")
    tr, te = valve_small.train, valve_small.test
    splits = {"train": tr.subset(range(6)), "valid": tr.subset([6, 7]),
              "test": Trajectories((te.u[0][:300],), (te.y[0][:300],))}
    data = save_dataset(valve_small.replace(splits=splits), root / "valve")
    params = root / "wrong.json"
    params.write_text(json.dumps(WRONG_VALVE))
    return data, params, root


@pytest.fixture(scope="module")
def trained(folders):
    data, params, root = folders
    out = root / "hybrid.pt"
    argv = ["train", "--data", str(data), "--arch", "hybrid", "--physics", "valve", "--physics-params", str(params),
            "--train-physics", "k_s,C_max", "--hidden", "8", "--epochs", "1", "--truncate", "50", "--quiet",
            "--out", str(out)]
    assert main(argv) == 0
    return out


def test_the_checkpoint_holds_the_hybrid(trained):
    ckpt = load_checkpoint(trained)  # torch.load(weights_only=True) inside
    config = ckpt["model_config"]
    assert config["arch"] == "hybrid" and config["physics"] == "valve"
    assert config["physics_params"] == dict(sorted(WRONG_VALVE.items()))
    assert config["train_physics"] == ["k_s", "C_max"] and ckpt["train_config"]["dtype"] == "float64"
    assert ckpt["history"][1]["valid_nrmse"] < ckpt["history"][0]["valid_nrmse"]  # one epoch already helps


def test_exported_fmu_validates_and_equals_load_model_simulate(trained, valve_small, tmp_path):
    fmu = tmp_path / "hybrid.fmu"
    proc = subprocess.run([sys.executable, "-m", "nnfmu.export", str(trained), "-o", str(fmu)],
                          check=False, capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    assert "29 parameters" in proc.stdout
    assert validate_fmu(str(fmu)) == []
    model = load_model(trained)
    assert isinstance(model, HybridStepModel)
    u = np.concatenate(valve_small.test.u)[:3500]  # 3500 steps: three test records back to back
    y0 = valve_small.test.y[0][0]
    expected = model.simulate(u, y0)
    with FmuSimulator(fmu, valve_small.input_names, valve_small.output_names, valve_small.Ts) as sim:
        got = sim.simulate(u, y0)
    assert np.ptp(expected, axis=0).min() > 0
    assert float(np.max(np.abs(got - expected) / np.abs(expected).max(axis=0))) < 1e-9


@pytest.mark.parametrize("extra,message", [
    (["--physics", "valve", "--strategy", "series-parallel"], "parallel mode only"),
    (["--physics", "valve", "--train-physics", "k_s,spring"], "unknown valve parameter(s) 'spring'"),
    (["--physics", "valve", "--physics-params", "missing.json"], "physics parameter file missing.json not found"),
    (["--physics", "valve", "--physics-params", "broken.json"], "is not valid JSON"),
    (["--physics", "valve", "--physics-params", "unknown.json"], "unknown valve parameter(s) 'stiffness'"),
    ([], "--arch hybrid needs --physics NAME|FILE.py:NAME"),
])
def test_bad_hybrid_options_are_one_clear_line(folders, tmp_path, capsys, monkeypatch, extra, message):
    data, _, _ = folders
    monkeypatch.chdir(tmp_path)
    (tmp_path / "broken.json").write_text("{k_s: 1}")
    (tmp_path / "unknown.json").write_text('{"stiffness": 1}')
    argv = ["train", "--data", str(data), "--arch", "hybrid", "--epochs", "1", "--quiet", "--out", "h.pt", *extra]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.startswith("nnfmu train: error: ") and message in err and "Traceback" not in err
    assert not (tmp_path / "h.pt").exists()


def test_hybrid_options_need_the_hybrid_arch(folders, tmp_path, capsys):
    data, _, _ = folders
    argv = ["train", "--data", str(data), "--arch", "gru", "--physics", "valve", "--out", str(tmp_path / "g.pt")]
    assert main(argv) == 2
    assert "--physics only apply to --arch hybrid" in capsys.readouterr().err


def test_an_unknown_physics_is_one_clear_line(folders, tmp_path, capsys):
    argv = ["train", "--data", str(folders[0]), "--arch", "hybrid", "--physics", "pendulum", "--out",
            str(tmp_path / "x.pt")]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert "'pendulum'" in err and "valve" in err and "Traceback" not in err


def test_the_command_line_choices_are_the_packages(capsys):
    from nnfmu.hybrid import BACKENDS, CORRECTIONS
    from nnfmu.models.architectures import architecture
    from nnfmu.physics import physics_names

    choices = {o.field: o.choices for o in architecture("hybrid").options}
    assert (choices["correction"], choices["physics_backend"]) == (CORRECTIONS, BACKENDS)
    with pytest.raises(SystemExit):
        main(["train", "--help"])
    physics_help = " ".join(capsys.readouterr().out.split()).partition("--physics NAME|FILE.py:NAME")[2]
    assert f"({', '.join(physics_names())}) or FILE.py:NAME" in physics_help


def test_the_hybrid_gets_a_budget_planned_from_the_data_on_whole_trajectories(folders, capsys):
    """At its defaults a hybrid on few records made one optimiser step an epoch and stopped after ~16 (issue 23)."""
    data, _, root = folders
    out = root / "planned.pt"
    argv = ["train", "--data", str(data), "--arch", "hybrid", "--physics", "valve", "--hidden", "4", "--epochs", "1",
            "--quiet", "--out", str(out)]
    assert main(argv) == 0
    printed = capsys.readouterr().out
    assert "plan: windows: whole trajectories (a hybrid's state starts from y0" in printed
    assert "plan: batch: 1 of 6 trajectories an epoch" in printed
    cfg = load_checkpoint(out)["train_config"]
    assert (cfg["batch_size"], cfg["truncate"], cfg["epochs"], cfg["patience"]) == (1, None, 1, 4000 // 6 + 1)


def test_max_minutes_alone_trains_one_hybrid_instead_of_a_search():
    """The budget plan does not make ``--max-minutes`` a search over the networks' knobs for a hybrid."""
    from nnfmu.cli._train_search import _planned
    assert not _planned("hybrid") and _planned("gru") and _planned(None)
