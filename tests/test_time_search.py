"""``nnfmu train --max-minutes N`` alone: the time-budget search (nnfmu.study.time_search), its space and its table."""

from __future__ import annotations

import time
import types
from pathlib import Path

import pytest

from nnfmu.cli._train_plan import TrainPlan, TrainRequest
from nnfmu.cli._train_search import applies, given_options, print_table, run_search
from nnfmu.errors import ConfigError
from nnfmu.models import ModelConfig, load_checkpoint
from nnfmu.study.time_space import HIDDEN, arch_order, LRS, NOISES, trial_configs, trial_points
from nnfmu.training import TrainConfig
from tests.test_linear import dataset, true_system


_MODEL = ("hidden", "layers", "window", "dropout", "init_window")


def _args(**changes) -> TrainRequest:
    """What ``nnfmu train`` asks for ``--max-minutes`` alone (``--max-minutes 0.5``) unless ``changes`` say
    otherwise (the argparse dests; None: left out)."""
    base = dict(arch=None, max_minutes=0.5, seeds=None, resume=False, increment=None, quiet=True)
    values = {**base, **changes}
    own = {"arch", "seeds", "resume", "increment", "quiet"}
    options = {k: v for k, v in values.items() if k not in own and v is not None}
    return TrainRequest(data="d", out=Path("m.pt"), arch=values["arch"], seeds=values["seeds"],
                        resume=values["resume"], increment=values["increment"], quiet=values["quiet"],
                        model_options={k: v for k, v in options.items() if k in _MODEL},
                        train_options={k: v for k, v in options.items() if k not in _MODEL})


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
    order = arch_order()  # read from the registry: an architecture with a search_rank joins by itself
    assert order[:5] == ("gru", "lstm", "tcn", "mlp", "rnn")
    assert [p["arch"] for p in points[:len(order)]] == list(order)  # gru (given as the base) first
    assert len({tuple(p.values()) for p in points}) == 12  # no point twice
    assert all(p["hidden"] in HIDDEN and p["lr"] in LRS and p["feedback_noise"] in NOISES
               and p["truncate"] in (200, 400, 800) for p in points)
    assert trial_points(model, train, set(), 12, seed=0, longest=5000) == points  # seeded
    assert trial_points(model, train, set(), 12, seed=1, longest=5000) != points
    whole = trial_points(model, TrainConfig(), set(), 12, seed=0, longest=5000)
    assert {p["truncate"] for p in whole} == {None}  # whole trajectories in the plan: the window is not searched
    assert {p["truncate"] for p in trial_points(model, train, set(), 30, 0, longest=500)} == {200, 400}  # fits


def test_an_architecture_that_feeds_back_no_output_is_searched_without_feedback_noise():
    # the ss network refuses feedback noise; drawn from the base GRU's noises, its trials ended before an epoch
    from nnfmu.models import architectures

    model, train = ModelConfig(arch="gru", n_u=2, n_y=1), TrainConfig(truncate=400)
    points = trial_points(model, train, set(), 60, seed=0, longest=5000)
    refusing = [p for p in points if not architectures.model_class(p["arch"]).takes_feedback_noise]
    assert refusing and all(p["feedback_noise"] == 0.0 for p in refusing)
    assert any(p["feedback_noise"] > 0 for p in points)  # the others still search it


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
    usage = {"cpu_s": 110.0, "cores": 2, "wall_s": 62.5, "cpu_share": 0.88, "workers_cpu_s": 113.0, "waited_s": 4.0,
             "load": 2.1}
    print_table(rows, kept=(0,), usage=usage)
    lines = capsys.readouterr().out.splitlines()
    assert lines[0].split()[:4] == ["trial", "arch", "hidden", "lr"]
    assert lines[1].split()[:2] == ["0*", "gru"] and "0.2500" in lines[1] and "12.5" in lines[1]
    assert lines[2].split()[:2] == ["1", "tcn"] and "diverged: the training loss became nan" in lines[2]
    assert lines[3].startswith("* kept")
    assert lines[4].startswith("CPU: the trials used 110 CPU-s of 2 cores x 62 s, 88 %; the workers spent 3 CPU-s "
                               "besides (start, imports) and waited 4 s for a core")


def test_successive_halving_stops_a_trial_trailing_at_a_rung_and_never_trial_zero():
    from nnfmu.study.trial_pool import Halving

    halving = Halving(grace=3)
    assert halving.keep(1, 3, 0.9)  # the first at a rung goes on
    assert halving.keep(2, 3, 0.5) and halving.keep(2, 4, 0.99)  # better; epoch 4 is no rung
    assert not halving.keep(3, 3, 0.95)  # worse than the best half at epoch 3
    assert halving.keep(0, 3, 2.0) and halving.keep(0, 6, 2.0)  # the defaults train to their own stop
    assert halving.stopped == {3}


def test_successive_halving_by_architecture_compares_a_slow_starter_only_with_its_own_kind():
    from nnfmu.study.trial_pool import Halving

    arch = {1: "gru", 2: "gru", 3: "ss", 4: "ss", 5: "ss"}
    halving = Halving(grace=3, group=arch.get)
    assert halving.keep(1, 3, 0.50) and halving.keep(2, 3, 0.40)  # two recurrent networks already below their start
    assert halving.keep(3, 3, 0.74)  # the first ss there, still at its linear start: not compared with the GRUs
    assert halving.keep(4, 3, 0.74)  # level with the ss before it
    assert not halving.keep(5, 3, 0.80)  # trails the ss trials
    assert halving.stopped == {5}
    mixed = Halving(grace=3)  # one group: the same ss trials against the GRUs' scores
    assert mixed.keep(1, 3, 0.50) and mixed.keep(2, 3, 0.40)
    assert not mixed.keep(3, 3, 0.74)


def test_once_every_point_started_the_best_points_that_trained_to_their_stop_train_again_with_further_seeds():
    from nnfmu.study.time_space import again

    point = {"arch": "gru", "hidden": 32, "lr": 3e-3, "feedback_noise": 0.0, "truncate": None}
    run = [{**point, "hidden": h, "seed": 0} for h in (8, 16, 32, 64)]
    scores, halved = {0: 0.5, 1: 0.3, 2: 0.4, 3: 0.2}, {3}  # trial 3 is best but was stopped early: not repeated
    assert again(run, {}, set(), 2) is None  # nothing finished yet
    picked = []
    for _ in range(3):
        run.append(again(run, scores, halved, 2))
        picked.append((run[-1]["hidden"], run[-1]["seed"]))
    assert picked == [(16, 1), (32, 1), (16, 2)]  # the two best points in turn, the better first


def test_a_further_seed_of_a_point_trains_to_its_own_stop_as_trial_zero_does():
    from nnfmu.study.time_search import _Jobs

    ds = dataset(true_system())
    model, train = ModelConfig(arch="gru", n_u=ds.n_u, n_y=ds.n_y), TrainConfig(epochs=50, patience=10)
    points = trial_points(model, train, {"arch", "lr", "feedback_noise", "truncate"}, 10, seed=0, longest=500)
    jobs = _Jobs(points, model, train, set(), ds, grace=3)
    assert [jobs.job(i)["train_config"]["seed"] for i in range(len(points))] == [0, 0, 0]  # the 3 widths
    assert jobs.job(3) is None  # every point started, none ended yet
    jobs.trials.scores.update({0: 0.4, 1: 0.3, 2: 0.5})
    again = jobs.job(3)
    assert (again["model_config"]["hidden"], again["train_config"]["seed"]) == (points[1]["hidden"], 1)
    for epoch in (3, 6, 12):  # far behind a trial that reached each rung before it, and never stopped
        assert jobs.halving.keep(1, epoch, 0.1) and jobs.halving.keep(3, epoch, 9.0)
    assert 3 not in jobs.halving.stopped


def test_halving_by_architecture_compares_a_trial_only_with_its_own_kind_and_all_with_every_trial(monkeypatch):
    from nnfmu.study import time_search
    from nnfmu.study.time_search import _Jobs

    ds = dataset(true_system())
    model, train = ModelConfig(arch="gru", n_u=ds.n_u, n_y=ds.n_y), TrainConfig(epochs=50, patience=10)
    points = trial_points(model, train, {"lr", "feedback_noise", "truncate"}, 12, seed=0, longest=500)

    def started(halving_by):
        monkeypatch.setattr(time_search, "HALVING_BY", halving_by)
        jobs = _Jobs(points, model, train, set(), ds, grace=3)
        return jobs, [jobs.job(i)["model_config"]["arch"] for i in range(len(points))]

    jobs, arch = started("arch")
    gru = next(i for i, a in enumerate(arch) if a == "gru" and i > 0)
    first, second = [i for i, a in enumerate(arch) if a == "lstm"][:2]
    assert jobs.halving.keep(gru, 3, 0.1) and jobs.halving.keep(first, 3, 0.5)
    assert jobs.halving.keep(second, 3, 0.5)  # level with the other LSTM, though far behind the GRU
    mixed, _ = started("all")  # one group, as before
    assert mixed.halving.keep(gru, 3, 0.1)
    assert not mixed.halving.keep(first, 3, 0.5) and not mixed.halving.keep(second, 3, 0.5)


def test_late_in_the_budget_a_free_core_trains_a_further_seed_of_a_best_point_before_the_next_new_point(
        monkeypatch):
    from nnfmu.study import time_search
    from nnfmu.study.time_search import _Jobs

    ds = dataset(true_system())
    model, train = ModelConfig(arch="gru", n_u=ds.n_u, n_y=ds.n_y), TrainConfig(epochs=50, patience=10)
    points = trial_points(model, train, {"arch", "lr", "feedback_noise", "truncate"}, 10, seed=0, longest=500)
    clock = [0.0]
    monkeypatch.setattr(time_search.time, "monotonic", lambda: clock[0])
    jobs = _Jobs(points, model, train, set(), ds, grace=3, reseed_at=100.0)
    assert jobs.job(0)["model_config"]["hidden"] == points[0]["hidden"]  # trial 0: the defaults
    assert jobs.job(1)["model_config"]["hidden"] == points[1]["hidden"]
    jobs.trials.scores.update({0: 0.4, 1: 0.3})  # both trained to their own stop
    clock[0] = 99.0  # before reseed_at: the space's next point
    assert jobs.job(2)["model_config"]["hidden"] == points[2]["hidden"] and not jobs.reseeds
    clock[0] = 100.0  # from reseed_at on: the best point that ended, with the next seed, trained to its own stop
    seed = jobs.job(3)
    assert (seed["model_config"]["hidden"], seed["train_config"]["seed"]) == (points[1]["hidden"], 1)
    assert jobs.reseeds == {3} and 3 in jobs.halving.exempt and jobs.started_points == 3


def test_a_trial_whose_worker_dies_is_a_failed_row_and_a_fresh_worker_takes_the_next(tmp_path):
    """A worker that ends in the middle of a trial (here: a job it cannot read) costs that trial only."""
    from nnfmu.data import save_dataset
    from nnfmu.study.trial_pool import Halving, Trials, run_trials

    ds = dataset(true_system())
    data = save_dataset(ds, tmp_path / "data")
    model = ModelConfig(arch="gru", n_u=ds.n_u, n_y=ds.n_y, hidden=4).to_dict()
    jobs = [{"trial": 0, "model_config": model},  # no train_config: the worker's KeyError ends it
            {"trial": 1, "model_config": model, "train_config": TrainConfig(epochs=2).to_dict()}]
    trials, done = Trials(), []
    run_trials(lambda i: jobs[i] if i < 2 else None, data=data, folder=tmp_path, linear=None, cpus=1,
               end=lambda: time.monotonic() + 120, min_left_s=1.0, halving=Halving(3), trials=trials,
               on_done=lambda i, record: done.append(i))
    assert done == [0, 1] and trials.started == 2
    assert trials.records[0]["status"] == "failed" and "KeyError: 'train_config'" in trials.records[0]["error"]
    assert trials.records[1]["status"] == "epochs" and trials.records[1]["last"]["epoch"] == 2
    assert trials.records[1]["cpu_s"] > 0 and (tmp_path / "trial-1.pt").is_file()


def _table(printed: str) -> list[list[str]]:
    lines = printed.splitlines()
    start = next(i for i, line in enumerate(lines) if line.split()[:2] == ["trial", "arch"])
    end = next(i for i, line in enumerate(lines) if line.startswith("* kept"))
    return [line.split() for line in lines[start + 1:end]]


def test_a_search_keeps_a_model_no_worse_on_validation_than_trial_zero_the_defaults_trained_to_their_stop(
        tmp_path, capsys):
    """A real search on a tiny linear system, its space cut to three points (the learning rate) so that it ends
    when they do: trial 0 is the plain training trained to its own stop (its epochs), the same numbers as train()
    gives, not stopped by the halving; the kept model is at or below it on validation; the table reports the trials'
    CPU time and share; ``keep_trials`` keeps every trial's checkpoint."""
    from nnfmu.study import time_search
    from nnfmu.training import train as train_network

    args = _args(max_minutes=2.0, hidden=8, feedback_noise=0.0, truncate=None, arch="gru")
    ds = dataset(true_system(), noise=0.05)
    model = ModelConfig(arch="gru", n_u=ds.n_u, n_y=ds.n_y, hidden=8)
    train = TrainConfig(epochs=12, patience=12, max_minutes=2.0)
    given = given_options(args)
    results = []
    real_search = time_search.search_for

    def recorded_search(*a, **k):
        results.append(real_search(*a, cpus=2, keep_trials=tmp_path / "trials", **k))
        return results[-1]

    out = tmp_path / "kept.pt"
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(time_search, "search_for", recorded_search)
        mp.setattr(time_search, "again", lambda *a: None)  # no further seeds: the search ends with its 3 points
        plan = TrainPlan(args.replace(out=out), ds, model, train, types.SimpleNamespace(type="cpu"), search=True,
                         given=frozenset(given))
        assert run_search(plan) == 0
    (result,) = results
    rows = result.rows
    assert [r["trial"] for r in rows] == [0, 1, 2] and {r["lr"] for r in rows} == {1e-3, 3e-3, 1e-2}
    assert {r["seed"] for r in rows} == {train.seed}
    assert (rows[0]["lr"], rows[0]["epochs"], rows[0]["status"], rows[0]["stopped"]) == (3e-3, 12, "epochs", False)
    plain = train_network(ds, model, train, device="cpu", threads=1)  # trial 0 is this training, in a worker
    # to float32 rounding: the compiled free run and torch's agree to it, and a process runs torch's where its C
    # library is unavailable (seen once in a full suite: 7e-8 apart); another learning rate differs by far more
    assert rows[0]["best_valid_nrmse"] == pytest.approx(plain.best_valid_nrmse, rel=1e-6)
    assert result.best_valid_nrmse <= rows[0]["best_valid_nrmse"]
    ckpt = load_checkpoint(out)
    assert ckpt["summary"]["best_valid_nrmse"] == result.best_valid_nrmse
    assert ckpt["summary"]["search"]["trials"] == 3 and ckpt["summary"]["test_nrmse"] == pytest.approx(result.test.mean)
    kept_trials = {p.name: load_checkpoint(p)["summary"]["best_valid_nrmse"] for p in (tmp_path / "trials").iterdir()}
    assert kept_trials == {f"trial-{r['trial']}.pt": r["best_valid_nrmse"] for r in rows}  # for offline comparisons
    usage = result.usage
    assert usage["cores"] == 2 and usage["cpu_s"] == pytest.approx(sum(r["cpu_s"] for r in rows))
    assert 0 < usage["cpu_share"] == pytest.approx(usage["cpu_s"] / (2 * usage["wall_s"]))
    printed = capsys.readouterr().out
    assert [row[0].rstrip("*") for row in _table(printed)] == ["0", "1", "2"]
    assert f"CPU: the trials used {usage['cpu_s']:.0f} CPU-s of 2 cores" in printed
    assert f"validation free-run NRMSE {result.best_valid_nrmse:.4f}" in printed


@pytest.mark.parametrize("finished", [True, False])
def test_an_interrupted_search_keeps_the_best_finished_trial_or_nothing(finished, tmp_path, monkeypatch, capsys):
    """Ctrl-C during the search (the workers' run replaced by one that trains trial 0 for an epoch, or not, and is
    interrupted): the best finished trial is written to out and the interrupt goes on; without one, nothing."""
    from nnfmu.study import time_search
    from nnfmu.training import train

    ds = dataset(true_system(), noise=0.05)

    def interrupted(job, *, folder, trials, **kwargs):
        trials.started = 2
        assert job(0)["model_config"]["arch"] == "gru" and job(1)["trial"] == 1
        if finished:
            train(ds, ModelConfig(arch="gru", n_u=ds.n_u, n_y=ds.n_y, hidden=4), TrainConfig(epochs=1),
                  out=folder / "trial-0.pt")
        raise KeyboardInterrupt

    monkeypatch.setattr(time_search, "run_trials", interrupted)
    out = tmp_path / "kept.pt"
    with pytest.raises(KeyboardInterrupt):
        time_search.search_for(ds, 1.0, model_config=None, train_config=TrainConfig(), out=out, cpus=2,
                               progress=False)
    assert out.exists() is finished
    if finished:
        search = load_checkpoint(out)["summary"]["search"]
        assert (search["trials"], search["kept"], search["members"]) == (2, 0, [0])  # no selection once stopped
        assert "search stopped (KeyboardInterrupt): the best trial so far, 0" in capsys.readouterr().out


def test_max_minutes_alone_searches_without_ray(monkeypatch):
    import sys

    monkeypatch.setitem(sys.modules, "ray", None)  # import ray -> ImportError: the search needs none
    assert applies(_args())


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


def _trials_on_disk(tmp_path, ds, linear, trials: list) -> list:
    """Checkpoints ``trial-<i>.pt`` of ``(arch, output offset, halved)`` each, and their rows with their real
    validation free-run NRMSE (as their trainings would have kept it)."""
    import torch

    from nnfmu.models import save_checkpoint
    from nnfmu.training.ensemble_select import ensemble_score
    from tests.test_linear_path import path_model

    rows = []
    for i, (arch, shift, halved) in enumerate(trials):
        model = path_model(arch, ds, linear)
        with torch.no_grad():
            model.lin_d.add_(shift)
        score = ensemble_score([model], ds.valid)[1]
        save_checkpoint(tmp_path / f"trial-{i}.pt", model, train_config=TrainConfig().to_dict(), best_epoch=5,
                        summary={"best_valid_nrmse": score, "epochs_run": 9})
        rows.append({"trial": i, "arch": arch, "hidden": 8, "lr": 3e-3, "feedback_noise": 0.0, "truncate": None,
                     "seed": i, "epochs": 9, "best_valid_nrmse": score, "stopped": halved, "cpu_s": 1.0,
                     "status": "time-budget", "error": None})
    return rows


def test_the_search_keeps_the_seeds_of_the_point_best_on_their_mean_not_the_luckiest_trial(tmp_path, capsys):
    """Two points with two seeds each: the MLP's seeds are the best trial of all (offset 0.05) and a poor one (0.9),
    the GRU's two are middling (+0.3, -0.32) and better on their mean. The kept model is the GRU's seeds joined,
    not the luckiest trial; a halved trial is no seed of its point; and where the point's ensemble would be worse
    on validation than trial 0, the defaults, the search keeps the greedy selection over its best trials."""
    from nnfmu.linear import identify_linear
    from nnfmu.study.time_search import _keep

    ds = dataset(true_system(), noise=0.01)
    linear = identify_linear(ds)
    rows = _trials_on_disk(tmp_path, ds, linear, [("gru", 0.3, False), ("mlp", 0.05, False), ("gru", -0.32, False),
                                                   ("mlp", 0.9, False), ("mlp", 0.04, True)])
    score = {r["trial"]: r["best_valid_nrmse"] for r in rows}
    assert min(score, key=score.get) == 4 and sorted(score, key=score.get)[1] == 1  # the luckiest: halved, then 1
    assert (score[0] + score[2]) / 2 < (score[1] + score[3]) / 2  # the GRU point is the better on its mean
    kept = _keep(rows, tmp_path, ds, tmp_path / "kept.pt", deadline=time.monotonic() + 600)
    assert kept.best == 4 and kept.members == (0, 2) and kept.member_scores[-1] < score[1]
    assert "seeds of the point best on their mean" in kept.selection and "gru h8" in kept.selection
    summary = load_checkpoint(tmp_path / "kept.pt")["summary"]
    assert summary["search"]["members"] == [0, 2] and summary["best_valid_nrmse"] == kept.member_scores[-1]

    # the GRU's seeds both off the same way: the best of them is above trial 0 (a TCN) on validation -> the greedy
    # selection over the best trials, from the best one
    rows = _trials_on_disk(tmp_path, ds, linear, [("tcn", 0.1, False), ("mlp", 0.05, False), ("gru", 0.3, False),
                                                  ("mlp", 0.9, False), ("gru", 0.35, False)])
    score = {r["trial"]: r["best_valid_nrmse"] for r in rows}
    assert (score[2] + score[4]) / 2 < (score[1] + score[3]) / 2 and score[0] < score[2]
    kept = _keep(rows, tmp_path, ds, tmp_path / "kept.pt", deadline=time.monotonic() + 600)
    assert kept.best == 1 and kept.members[0] == 1 and "seeds of the point" not in kept.selection
