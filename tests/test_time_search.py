"""``nnfmu train --max-minutes N`` alone: the time-budget search (nnfmu.study.time_search), its space and its table."""

from __future__ import annotations

import argparse
import contextlib
import re
import time
import types

import pytest

from nnfmu.cli._train_search import applies, given_options, print_table, run_search
from nnfmu.errors import ConfigError
from nnfmu.models import ModelConfig, load_checkpoint
from nnfmu.study.time_space import HIDDEN, arch_order, LRS, NOISES, trial_configs, trial_points
from nnfmu.training import TrainConfig
from tests.test_linear import dataset, true_system


def _args(**changes) -> argparse.Namespace:
    """The namespace ``nnfmu train`` parses, for ``--max-minutes`` alone unless ``changes`` say otherwise."""
    base = dict(arch=None, hidden=None, layers=None, window=None, dropout=None, init_window=None, lr=None,
                feedback_noise=None, truncate=None, max_minutes=0.5, epochs=None, patience=None, seeds=None,
                resume=False, increment=None, quiet=True, linear_path="auto")
    return argparse.Namespace(**{**base, **changes})


@pytest.mark.parametrize("changes, searches", [
    ({}, True), ({"arch": "lstm"}, True), ({"max_minutes": None}, False), ({"epochs": 10}, False),
    ({"patience": 5}, False), ({"seeds": 3}, False), ({"resume": True}, False), ({"increment": "on"}, False),
    ({"arch": "hybrid"}, False)])
def test_the_search_applies_to_max_minutes_alone_on_a_new_network(changes, searches):
    assert applies(_args(**changes)) is searches


def test_trial_zero_is_the_plain_training_and_the_rest_take_the_architectures_in_turn():
    model, train = ModelConfig(arch="gru", n_u=2, n_y=1), TrainConfig(truncate=400)
    points = trial_points(model, train, set(), 12, seed=0, longest=5000)
    assert points[0] == {"arch": "gru", "hidden": 32, "lr": 3e-3, "feedback_noise": 0.0, "truncate": 400}
    assert [p["arch"] for p in points[:6]] == list(arch_order()) == ["gru", "lstm", "tcn", "mlp", "rnn", "ss"]  # gru first
    assert len({tuple(p.values()) for p in points}) == 12  # no point twice
    assert all(p["hidden"] in HIDDEN and p["lr"] in LRS and p["feedback_noise"] in NOISES
               and p["truncate"] in (200, 400, 800) for p in points)
    assert trial_points(model, train, set(), 12, seed=0, longest=5000) == points  # seeded
    assert trial_points(model, train, set(), 12, seed=1, longest=5000) != points
    whole = trial_points(model, TrainConfig(), set(), 12, seed=0, longest=5000)
    assert {p["truncate"] for p in whole} == {None}  # whole trajectories in the plan: the window is not searched
    assert {p["truncate"] for p in trial_points(model, train, set(), 30, 0, longest=500)} == {200, 400}  # fits


def test_the_options_given_stay_fixed_in_every_trial():
    model = ModelConfig(arch="tcn", n_u=2, n_y=1, hidden=8, layers=2, linear_order=3)
    train = TrainConfig(lr=0.02, truncate=300, feedback_noise=0.3)
    given = given_options(_args(arch="tcn", hidden=8, layers=2, lr=0.02, truncate=300, feedback_noise=0.3))
    points = trial_points(model, train, given, 10, seed=0, longest=5000)
    assert points == [{"arch": "tcn", "hidden": 8, "lr": 0.02, "feedback_noise": 0.3, "truncate": 300}]
    # the architecture searched, the layers given: kept in every architecture, the linear path too
    given = given_options(_args(layers=2))
    for point in trial_points(model, train, given, 10, seed=0, longest=5000):
        m, t = trial_configs(point, model, train, given)
        assert (m.arch, m.hidden, m.layers, m.linear_order) == (point["arch"], point["hidden"], 2, 3)
        assert (t.lr, t.truncate, t.feedback_noise) == (point["lr"], point["truncate"], point["feedback_noise"])
    # a given --window that a recurrent network cannot take: only the MLP is searched
    mlp = ModelConfig(arch="mlp", n_u=2, n_y=1, window=8)
    archs = {p["arch"] for p in trial_points(mlp, train, given_options(_args(window=8)), 20, 0, longest=5000)}
    assert archs == {"mlp"}


def test_the_search_needs_a_validation_split_and_a_positive_budget(tmp_path):
    from nnfmu.study.time_search import search_for

    ds = dataset(true_system())
    model, train = ModelConfig(arch="gru", n_u=ds.n_u, n_y=ds.n_y), TrainConfig()
    no_valid = ds.replace(splits={k: v for k, v in ds.splits.items() if k != "valid"})
    with pytest.raises(ConfigError, match="validation split"):
        search_for(no_valid, 0.5, model_config=model, train_config=train, out=tmp_path / "m.pt")
    with pytest.raises(ConfigError, match="> 0 minutes"):
        search_for(ds, 0, model_config=model, train_config=train, out=tmp_path / "m.pt")
    assert not (tmp_path / "m.pt").exists()


def test_the_table_has_a_row_per_trial_and_marks_the_kept_one(capsys):
    rows = [{"trial": 0, "arch": "gru", "hidden": 32, "lr": 3e-3, "feedback_noise": 0.0, "truncate": None,
             "epochs": 40, "best_valid_nrmse": 0.25, "stopped": False, "cpu_s": 12.5, "status": "time-budget",
             "error": None},
            {"trial": 1, "arch": "tcn", "hidden": 16, "lr": 1e-2, "feedback_noise": 0.1, "truncate": 400,
             "epochs": 0, "best_valid_nrmse": None, "stopped": False, "cpu_s": None, "status": "diverged",
             "error": "the training loss became nan"}]
    print_table(rows, kept=(0,))
    lines = capsys.readouterr().out.splitlines()
    assert lines[0].split()[:4] == ["trial", "arch", "hidden", "lr"]
    assert lines[1].split()[:2] == ["0*", "gru"] and "0.2500" in lines[1] and "12.5" in lines[1]
    assert lines[2].split()[:2] == ["1", "tcn"] and "diverged: the training loss became nan" in lines[2]
    assert lines[3].startswith("* kept")


@pytest.mark.parametrize("record", ["", '{"status": "time-bud'])
def test_a_trial_record_cut_off_by_the_end_of_the_search_is_a_row_not_a_traceback(tmp_path, record):
    """Tune's time budget may end a worker while it writes its record (a 10-minute robot search was lost to
    'JSONDecodeError' at its end): the row says Ray ended the trial, and the search keeps the others."""
    from nnfmu.study.time_search import _row

    (tmp_path / "trial-3.json").write_text(record)
    point = {"arch": "gru", "hidden": 32, "lr": 3e-3, "feedback_noise": 0.0, "truncate": 200}
    row = _row(3, point, tmp_path, stopped=False, last={"cpu_s": 4.0})
    assert row["trial"] == 3 and row["epochs"] == 0 and row["best_valid_nrmse"] is None
    assert row["status"].startswith("ended by Ray") and row["cpu_s"] == 4.0


def _table(printed: str) -> list[list[str]]:
    lines = printed.splitlines()
    start = next(i for i, line in enumerate(lines) if line.split()[:2] == ["trial", "arch"])
    end = next(i for i, line in enumerate(lines) if line.startswith("* kept"))
    return [line.split() for line in lines[start + 1:end]]


@pytest.mark.slow
def test_a_search_in_a_local_loopback_ray_keeps_the_best_trial(tmp_path, capsys, monkeypatch):
    """A real search of 2.5 minutes on a tiny linear system (Ray's start takes 10-30 s of it on 2 busy cores, and
    the suite's other worker keeps one of them busy)."""
    import psutil
    import ray

    from nnfmu.cli._train_plan import prepare
    from nnfmu.limits import UNBOUNDED_EPOCHS
    from nnfmu.study import time_search

    seen, results, real_session, real_search = {}, [], time_search.ray_session, time_search.search_for

    @contextlib.contextmanager
    def watched_session(*args, **kwargs):
        with real_session(*args, **kwargs) as handle:
            seen["gcs"] = handle.get_runtime_context().gcs_address
            ours = {p.pid for p in psutil.Process().children(recursive=True)}
            seen["listening"] = {c.laddr.ip for c in psutil.net_connections("tcp")
                                 if c.status == psutil.CONN_LISTEN and c.pid in ours}
            yield handle

    def recorded_search(*args, **kwargs):
        results.append(real_search(*args, **kwargs))
        return results[-1]

    monkeypatch.setattr(time_search, "ray_session", watched_session)
    monkeypatch.setattr(time_search, "search_for", recorded_search)
    args = _args(max_minutes=2.5, started=time.monotonic())  # the budget counts from the command's start
    ds = dataset(true_system(), noise=0.05)
    model = ModelConfig(arch="gru", n_u=ds.n_u, n_y=ds.n_y)
    train = TrainConfig(max_minutes=2.5, epochs=UNBOUNDED_EPOCHS, patience=0)
    given = {"max_minutes": 2.5}
    ds, model, train, linear = prepare(args, ds, model, train, given)
    out = tmp_path / "kept.pt"
    assert run_search(args, ds, model, train, out, types.SimpleNamespace(type="cpu"), linear, given) == 0

    assert seen["gcs"].startswith("127.0.0.1:") and seen["listening"]
    assert seen["listening"] <= {"127.0.0.1", "::ffff:127.0.0.1"}  # nothing of Ray's listens on the network
    assert not ray.is_initialized()  # stopped by the handle that started it
    (result,) = results
    rows = result.rows
    assert len(rows) >= 2 and [r["trial"] for r in rows] == list(range(len(rows)))
    scored = [r["best_valid_nrmse"] for r in rows if r["best_valid_nrmse"] is not None]
    ckpt = load_checkpoint(out)
    assert result.best_valid_nrmse == ckpt["summary"]["best_valid_nrmse"] <= min(scored)
    assert rows[result.best]["best_valid_nrmse"] == min(scored) and result.members[0] == result.best
    members = [rows[i] for i in result.members]  # the best trial alone, or the ensemble that beat it on validation
    configs = ckpt["model_config"].get("member_configs") or [ckpt["model_config"]]
    assert [(c["arch"], c["hidden"]) for c in configs] == [(r["arch"], r["hidden"]) for r in members]
    assert ckpt["summary"]["search"]["trials"] == len(rows)
    assert ckpt["summary"]["test_nrmse"] == pytest.approx(result.test.mean)
    printed = capsys.readouterr().out
    table = _table(printed)
    assert [row[0].rstrip("*") for row in table] == [str(r["trial"]) for r in rows]  # every trial, one row each
    assert sorted(row[0] for row in table if row[0].endswith("*")) == sorted(f"{i}*" for i in result.members)
    assert re.search(rf"test free-run NRMSE: {result.test.mean:.4f} ", printed)
    assert f"validation free-run NRMSE {result.best_valid_nrmse:.4f}" in printed


@pytest.mark.parametrize("finished", [True, False])
def test_an_interrupted_search_keeps_the_best_finished_trial_or_nothing(finished, tmp_path, monkeypatch, capsys):
    """Ctrl-C during the search (Ray's run replaced by one that trains trial 0 for an epoch, or not, and is
    interrupted): the best finished trial is written to out and the interrupt goes on; without one, nothing."""
    from ray import tune

    from nnfmu.study import time_search
    from nnfmu.training import train

    ds = dataset(true_system(), noise=0.05)

    class InterruptedTuner:
        def __init__(self, trainable, *, run_config, tune_config):
            self.folder = __import__("pathlib").Path(run_config.storage_path).parent
            self.searcher = tune_config.search_alg

        def fit(self):
            assert self.searcher.suggest("a") == {"trial": 0} and self.searcher.suggest("b") == {"trial": 1}
            if finished:
                train(ds, ModelConfig(arch="gru", n_u=ds.n_u, n_y=ds.n_y, hidden=4), TrainConfig(epochs=1),
                      out=self.folder / "trial-0.pt")
            raise KeyboardInterrupt

    monkeypatch.setattr(time_search, "ray_session", lambda *a, **k: contextlib.nullcontext())
    monkeypatch.setattr(tune, "Tuner", InterruptedTuner)
    monkeypatch.setattr(tune, "with_parameters", lambda f, **kwargs: f)
    monkeypatch.setattr(tune, "with_resources", lambda f, resources: f)
    out = tmp_path / "kept.pt"
    with pytest.raises(KeyboardInterrupt):
        time_search.search_for(ds, 1.0, model_config=None, train_config=TrainConfig(), out=out, cpus=2,
                               progress=False)
    assert out.exists() is finished
    if finished:
        search = load_checkpoint(out)["summary"]["search"]
        assert (search["trials"], search["kept"], search["members"]) == (2, 0, [0])  # no selection once stopped
        assert "search stopped (KeyboardInterrupt): the best trial so far, 0" in capsys.readouterr().out


def test_without_ray_max_minutes_alone_trains_one_network_after_a_note(monkeypatch, capsys):
    import sys

    from nnfmu.cli import _train_search

    monkeypatch.setitem(sys.modules, "ray", None)  # import ray -> ImportError
    monkeypatch.setattr(_train_search, "_noted", [])
    assert not applies(_args()) and not applies(_args())
    printed = capsys.readouterr().out
    assert printed.count('searches with Ray Tune, which is not installed (pip install "nnfmu[tune]")') == 1


def test_the_search_keeps_an_ensemble_of_trials_only_when_it_beats_the_best_on_validation(tmp_path, capsys):
    """Three finished trials: two whose errors cancel (their linear path's output offset moved by +-0.3 output
    standard deviations) and a copy of the better one. The kept model is the ensemble of the two, written as one
    checkpoint that loads, exports and reports what it is; without the second one, the best trial alone."""
    import torch

    from nnfmu.models import save_checkpoint
    from nnfmu.study.time_search import _keep
    from tests.test_linear_path import path_model

    ds = dataset(true_system(), noise=0.01)
    from nnfmu.linear import identify_linear

    linear = identify_linear(ds)
    rows = []
    for i, (arch, shift) in enumerate((("gru", 0.3), ("mlp", 0.3), ("tcn", -0.32))):
        model = path_model(arch, ds, linear)
        with torch.no_grad():
            model.lin_d.add_(shift)
        save_checkpoint(tmp_path / f"trial-{i}.pt", model, train_config=TrainConfig().to_dict(), best_epoch=5,
                        summary={"best_valid_nrmse": 0.5 + 0.01 * i, "epochs_run": 9})
        rows.append({"trial": i, "arch": arch, "hidden": 8, "lr": 3e-3, "feedback_noise": 0.0, "truncate": None,
                     "epochs": 9, "best_valid_nrmse": 0.5 + 0.01 * i, "stopped": False, "cpu_s": 1.0,
                     "status": "time-budget", "error": None})
    kept = _keep(rows, tmp_path, ds, tmp_path / "kept.pt", deadline=time.monotonic() + 600)
    assert kept.best == 0 and kept.members == (0, 2) and kept.member_scores[1] < 0.5 * kept.member_scores[0]
    ckpt = load_checkpoint(tmp_path / "kept.pt")
    assert [c["arch"] for c in ckpt["model_config"]["member_configs"]] == ["gru", "tcn"]
    assert ckpt["summary"]["search"]["members"] == [0, 2] and ckpt["summary"]["best_valid_nrmse"] < 0.1
    assert ckpt["meta"]["name"].endswith("_ensemble")  # the FMU's model name says what it is
    from nnfmu.export import casadi_model
    from nnfmu.models import load_model

    ensemble = load_model(tmp_path / "kept.pt").double()
    u, y = ds.test.u[0], ds.test.y[0]
    assert abs(casadi_model(ensemble).simulate(u, y[0]) - ensemble.simulate(u, y[0])).max() < 1e-9
    print_table(rows, kept.members)
    assert [line.split()[0] for line in capsys.readouterr().out.splitlines()[1:4]] == ["0*", "1", "2*"]

    (tmp_path / "trial-2.pt").unlink()
    rows[2]["best_valid_nrmse"] = None
    alone = _keep(rows, tmp_path, ds, tmp_path / "kept.pt", deadline=time.monotonic() + 600)
    assert alone.members == (0,) and alone.best_valid_nrmse == 0.5 and "lowered" in alone.selection
    assert "member_configs" not in load_checkpoint(tmp_path / "kept.pt")["model_config"]  # as any one network's
