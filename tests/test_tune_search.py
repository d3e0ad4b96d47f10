"""``nnfmu tune`` (issue 24 item 14): --quiet, --threads, --arch's help, and a search that never trains a grid
point twice (:class:`nnfmu.study.no_repeat.NoRepeat`)."""

from __future__ import annotations

import json
from unittest import mock

import pytest

from nnfmu.cli import build_parser, command_parser, main
from nnfmu.study import require_ray

optuna = pytest.importorskip("optuna", reason="the extra 'search' (Optuna) is part of the dev install")


def _suggestions(searcher, n: int) -> list:
    """``n`` proposals of ``searcher`` on a 2 x 2 grid, each completed with a score before the next."""
    from ray import tune

    searcher.set_search_properties("nrmse", "min", {"hidden": tune.choice([4, 8]), "lr": tune.choice([1, 2])})
    out = []
    for i in range(n):
        config = searcher.suggest(f"t{i}")
        out.append(config if isinstance(config, str) else (config["hidden"], config["lr"]))
        if not isinstance(config, str):
            searcher.on_trial_complete(f"t{i}", {"nrmse": config["hidden"] * 0.1 + config["lr"]})
    return out


def test_optuna_repeats_a_grid_point_and_no_repeat_does_not():
    from ray.tune.search import Searcher
    from ray.tune.search.optuna import OptunaSearch

    from nnfmu.study.no_repeat import NoRepeat

    optuna.logging.set_verbosity(optuna.logging.WARNING)
    plain = _suggestions(OptunaSearch(sampler=optuna.samplers.TPESampler(seed=0)), 6)
    assert len(set(plain)) < len(plain)  # what the issue saw: TPE proposes a tried point again
    wrapped = _suggestions(NoRepeat(OptunaSearch(sampler=optuna.samplers.TPESampler(seed=0))), 6)
    assert sorted(wrapped[:4]) == [(4, 1), (4, 2), (8, 1), (8, 2)]  # every point once,
    assert wrapped[4:] == [Searcher.FINISHED] * 2  # then the search ends: the grid is exhausted


def test_tune_options_have_help_and_threads_sets_the_cpus_per_trial(valve_small_dir, tmp_path):
    tune = command_parser(build_parser(), "tune")
    helps = {a.dest: a.help for a in tune._actions}
    assert helps["arch"] and helps["quiet"] and helps["threads"]
    with mock.patch("nnfmu.study.tune_architecture", side_effect=RuntimeError("stop")) as tune_architecture:
        with pytest.raises(RuntimeError, match="stop"):
            main(["tune", "--data", str(valve_small_dir), "--arch", "gru", "--threads", "2", "--quiet",
                  "-o", str(tmp_path / "b.json")])
    settings, progress = tune_architecture.call_args.kwargs["settings"], tune_architecture.call_args.kwargs["progress"]
    assert settings.cpus_per_trial == 2 and settings.threads == 2 and progress is False


def test_threads_and_cpus_per_trial_must_agree(valve_small_dir, tmp_path, capsys):
    assert main(["tune", "--data", str(valve_small_dir), "--arch", "gru", "--threads", "1", "--cpus-per-trial", "2",
                 "-o", str(tmp_path / "b.json")]) == 2
    assert "--threads 1 and --cpus-per-trial 2 disagree" in capsys.readouterr().err


def test_a_quiet_optuna_search_trains_each_point_once_and_prints_only_the_result(valve_small_dir, tmp_path,
                                                                                  capsys):
    ray, _ = require_ray()
    if ray.is_initialized():
        ray.shutdown()  # the command starts its own instance, as a user's run does
    best = tmp_path / "best.json"
    assert main(["tune", "--data", str(valve_small_dir), "--arch", "gru", "--grid", "hidden=4,8", "--epochs", "1",
                 "--budget", "smoke", "--search", "optuna", "--trials", "4", "--cpus", "1", "--quiet",
                 "--storage", str(tmp_path / "ray"), "-o", str(best)]) == 0
    captured = capsys.readouterr()
    hidden = sorted(t["hidden"] for t in json.loads(best.read_text())["trials"])
    assert hidden == [4, 8]  # four trials asked for, but the grid has two points: each trained once
    assert "Trial status" not in captured.out + captured.err and "│" not in captured.out + captured.err
    assert "A new study created" not in captured.err  # Optuna's INFO line
    lines = [line for line in captured.out.splitlines() if line.strip()]  # the device line, then the result
    assert lines[0].startswith("device: cpu") and lines[1].startswith("2 trials of gru"), captured.out
