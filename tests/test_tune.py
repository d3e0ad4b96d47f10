"""Hyperparameter search on Ray Tune, for real in a local Ray instance, and its errors."""

from __future__ import annotations

import json
import sys

import pytest

from nnfmu.cli import main
from nnfmu.errors import ConfigError, UnknownOptionError
from nnfmu.study import Hyper, MissingExtraError, TuneResult, get_budget, reproduce, require_ray
from nnfmu.models.base import torch_threads
from nnfmu.study.tune import _best, check_grid


@pytest.fixture(scope="module")
def local_ray():
    """One local Ray instance (2 CPUs, no dashboard) for this module; the searches reuse it."""
    ray, _ = require_ray()
    ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False)
    yield ray
    ray.shutdown()


def test_tune_cli_searches_the_grid_and_writes_the_best(local_ray, valve_small, valve_small_dir, tmp_path, capsys):
    from nnfmu.training import train

    best_file = tmp_path / "best.json"
    assert main(["tune", "--data", str(valve_small_dir), "--arch", "gru", "--grid", "hidden=4,8", "--epochs", "1",
                 "--budget", "smoke", "--storage", str(tmp_path / "ray"), "--out", str(best_file)]) == 0
    printed = capsys.readouterr().out
    doc = json.loads(best_file.read_text())
    assert doc["ray_version"] == local_ray.__version__
    scores = {t["hidden"]: t["best_valid_nrmse"] for t in doc["trials"]}
    assert sorted(scores) == [4, 8] and all(t["epochs"] == 1 and t["error"] is None for t in doc["trials"])
    assert doc["best"]["hidden"] == min(scores, key=scores.get)
    assert doc["best_valid_nrmse"] == min(scores.values())
    assert f"--hidden {doc['best']['hidden']}" in printed and "train with: nnfmu train" in printed
    # each trial reported what the one trainer gives for its configuration
    base = get_budget("valve", "smoke").hyper["gru"]
    for hidden, score in scores.items():
        hyper = base.replace(hidden=hidden)
        with torch_threads(1):  # as in the trial (and much faster beside another busy process)
            direct = train(valve_small, hyper.model_config("gru", 2, 2),
                           hyper.train_config(strategy="parallel", epochs=1, patience=0, seed=0, max_minutes=None))
        assert score == pytest.approx(direct.best_valid_nrmse, rel=1e-9)
    assert TuneResult.load(best_file).best == base.replace(hidden=doc["best"]["hidden"])


def test_reproduce_with_tune_trains_the_tuned_configuration(local_ray, tmp_path):
    budget = get_budget("valve", "smoke").replace(archs=("rnn",), strategies=("parallel",))
    result = reproduce("valve", tmp_path / "study", budget=budget, tune=True, progress=False, echo=None)
    assert result.log.ran[:3] == ["data", "tune rnn parallel", "train rnn parallel"]
    tuned = TuneResult.load(tmp_path / "study" / "tune" / "rnn-parallel.json")
    assert len(tuned.trials) == 2 and tuned.best.hidden in (4, 8)
    (row,) = result.results["networks"]
    assert row["model_config"]["hidden"] == tuned.best.hidden and result.results["tuned"] is True
    assert row["nrmse"] is not None


def test_missing_ray_names_the_extra(monkeypatch, valve_small_dir, tmp_path, capsys):
    monkeypatch.setitem(sys.modules, "ray", None)  # import ray -> ImportError
    with pytest.raises(MissingExtraError, match=r'pip install "nnfmu\[tune\]"'):
        require_ray()
    assert main(["tune", "--data", str(valve_small_dir), "--arch", "gru"]) == 2
    assert 'install the optional extra with: pip install "nnfmu[tune]"' in capsys.readouterr().err
    with pytest.raises(MissingExtraError):  # said before any cell runs: nothing is written
        reproduce("valve", tmp_path / "study", budget="smoke", tune=True, progress=False, echo=None)
    assert not (tmp_path / "study").exists()


def test_an_invalid_grid_fails_before_ray_starts():
    with pytest.raises(ConfigError, match="tune grid point {'window': 4} is invalid for tcn"):
        check_grid("tcn", Hyper(layers=3), {"window": (4,)}, 2, 2)


@pytest.mark.parametrize("value", ["nan", "-1", "inf", "0"])
def test_a_training_value_outside_trains_range_fails_before_ray_starts(value):
    with pytest.raises(ConfigError, match="tune grid point .*lr.* is invalid for gru: lr must be"):
        check_grid("gru", Hyper(), {"lr": (0.001, float(value))}, 1, 1)


@pytest.mark.parametrize("grid, flag", [(["lr=0.001,nan"], "--grid lr"), (["lr=-1"], "--grid lr"),
                                        (["lr=20"], "--grid lr"), (["hidden=0"], "--grid hidden"),
                                        (["dropout=1.5"], "--grid dropout")])
def test_the_cli_grid_follows_the_train_options_rules(tmp_path, capsys, monkeypatch, grid, flag):
    from fmu_cases import oscillator_dataset

    import nnfmu.study.tune

    monkeypatch.setattr(nnfmu.study.tune, "ray_session", None)  # Ray must not start
    data = oscillator_dataset(tmp_path / "data")
    out = tmp_path / "best.json"
    assert main(["tune", "--data", str(data), "--arch", "gru", "--system", "valve", "--grid", *grid,
                 "-o", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith(f"nnfmu tune: error: {flag} must be") and "\n" not in err, err
    assert not out.exists()


@pytest.mark.parametrize("grid, error, match", [
    (["hidden"], ConfigError, "expects FIELD=V1,V2"),
    (["hiden=3"], UnknownOptionError, "unknown --grid option"),
    (["hidden=a,b"], ConfigError, "give int values"),
])
def test_grid_option_errors(grid, error, match):
    from nnfmu.cli.tune import parse_grid

    with pytest.raises(error, match=match):
        parse_grid(grid)


def test_grid_option_parses_typed_values():
    from nnfmu.cli.tune import parse_grid

    assert parse_grid(["hidden=16,32", "lr=1e-3,0.003", "truncate=none,100"]) == {
        "hidden": (16, 32), "lr": (0.001, 0.003), "truncate": (None, 100)}


def test_the_best_point_has_the_lowest_mean_over_repeats():
    scores = {(8, 0): 0.10, (8, 1): 0.90, (16, 0): 0.30, (16, 1): 0.40, (32, 0): None, (32, 1): 0.05}  # None: diverged
    trials = [{"hidden": h, "repeat": r, "best_valid_nrmse": s} for (h, r), s in scores.items()]
    result = _best("gru", "parallel", Hyper(), {"hidden": (8, 16, 32)}, trials, "x")
    assert result.best.hidden == 16 and result.best_valid_nrmse == pytest.approx(0.35)
