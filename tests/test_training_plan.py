"""Training that fits the data by default (issue 21): the plan's choices, the ensemble's guard against seeds that
never trained, feedback noise that does not integrate in increment mode, and checkpoints written on improvement."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import torch

from nnfmu.data import from_arrays
from nnfmu.models import ModelConfig, build_model
from nnfmu.training import TrainConfig, train
from nnfmu.training import ensemble as seeds_module
from nnfmu.training.plan import MAX_WINDOW, plan_training, still_improving, valid_fraction
from nnfmu.training.resources import usable_cores

pytestmark = pytest.mark.usefixtures("one_thread")


def one_record(n: int = 4000, test: int = 1000):
    rng = np.random.default_rng(0)
    u = rng.normal(size=(n + test, 1))
    y = np.cumsum(u, axis=0) * 0.01  # an integrator
    return from_arrays(Ts=0.1, u_train=[u[:n]], y_train=[y[:n]], u_test=[u[n:]], y_test=[y[n:]])


class _Integrator:
    """What the plan reads of a linear model: its A (a pole at 1, an integrating plant)."""
    n_x = 1

    class system:
        A = np.array([[1.0]])


def test_one_long_record_gets_windows_many_steps_and_a_test_like_validation_tail():
    ds = one_record(10000, 2000)
    plan = plan_training(ds, {}, linear=_Integrator())
    c = plan.changes
    assert c["truncate"] == MAX_WINDOW  # an integrating mode: the longest windows
    assert c["valid_fraction"] == pytest.approx(0.2)  # min(test length 2000, 25 %) of 10000 samples
    assert c["batch_size"] == 1 and c["epochs"] >= 500  # 4 windows an epoch: thousands of optimiser steps
    assert any("windows: --truncate" in line for line in plan.lines)


def test_the_init_window_is_counted_into_the_validation_tail():
    ds = one_record()
    assert valid_fraction(ds, init_window=201) == pytest.approx(valid_fraction(ds) + 200 / 4000)


def pieces(contiguous: bool):
    """Ten 500-sample pieces cut from one recording of an integrator (the robot benchmark's layout, smaller)."""
    rng = np.random.default_rng(1)
    u = rng.normal(size=(6000, 1))
    y = np.cumsum(u, axis=0) * 0.01
    return from_arrays(Ts=0.1, u_train=u[:5000].reshape(10, 500, 1), y_train=y[:5000].reshape(10, 500, 1),
                       u_valid=[u[5000:5500]], y_valid=[y[5000:5500]], u_test=[u[5500:]], y_test=[y[5500:]],
                       source={"contiguous": contiguous})


def test_consecutive_pieces_of_one_recording_are_joined_for_windows_longer_than_a_piece():
    plan = plan_training(pieces(True), {}, linear=_Integrator())
    # joined: 5000 samples, so windows of MAX_WINDOW across the seams, not 10 whole 500-sample pieces
    assert plan.changes["join"] is True and plan.changes["truncate"] == MAX_WINDOW
    assert any("joined end to end" in line for line in plan.lines)
    apart = plan_training(pieces(False), {}, linear=_Integrator())
    assert "join" not in apart.changes and "truncate" not in apart.changes  # pieces of unknown origin stay apart
    told = plan_training(pieces(True), {"join": False}, linear=_Integrator())  # --no-join
    assert "join" not in told.changes and "truncate" not in told.changes
    whole = plan_training(pieces(True), {"truncate": None}, linear=_Integrator())  # a hybrid's whole trajectories
    assert "join" not in whole.changes and whole.changes["batch_size"] == 2
    no_valid = pieces(True).replace(splits={k: v for k, v in pieces(True).splits.items() if k != "valid"})
    assert "join" not in plan_training(no_valid, {}, linear=_Integrator()).changes  # random validation pieces: gaps


def test_what_the_user_gives_is_kept_as_given():
    plan = plan_training(one_record(), {"truncate": 100, "batch_size": 7, "epochs": 5, "patience": 2,
                                        "valid_fraction": 0.1})
    assert plan.changes == {}


def test_still_improving_is_said_only_when_the_best_epoch_is_at_the_end():
    history = [{"epoch": k} for k in range(101)]
    assert still_improving(history, 97, "epochs") and not still_improving(history, 50, "epochs")
    assert not still_improving(history, 100, "early-stopping")


def test_an_ensemble_drops_a_seed_that_never_trained_and_says_so():
    config = ModelConfig(arch="mlp", n_u=1, n_y=1, hidden=4)
    models = [build_model(config).eval() for _ in range(3)]
    rows = [{"seed": s, "best_epoch": e, "best_valid_nrmse": v} for s, e, v in ((0, 4, 0.5), (1, 0, 0.9), (2, 7, 0.6))]
    ds = one_record(200, 50)
    model, _, notes, kept = seeds_module._ensemble_of_trained(models, rows, ds.test, 1)
    assert kept == [0, 2] and len(model.members) == 2 and torch.equal(model.members[1].net[0].weight, models[2].net[0].weight)
    assert any("dropped seed 1" in n and "never improved" in n for n in notes)
    alone, valid, notes, kept = seeds_module._ensemble_of_trained(models, [dict(r, best_epoch=0) for r in rows],
                                                                  ds.test, 1)
    assert kept == [0] and alone is models[0] and valid == 0.5 and any("kept seed 0 alone" in n for n in notes)
    # an ensemble worse on validation than where the seeds started is not kept: the best seed is
    started = [dict(r, start_valid_nrmse=1e-9) for r in rows]
    alone, valid, notes, kept = seeds_module._ensemble_of_trained(models, started, ds.test, 1)
    assert kept == [0] and alone is models[0] and valid == 0.5 and any("above the seeds' start" in n for n in notes)


@pytest.mark.parametrize("arch", ("gru", "mlp", "tcn"))
def test_feedback_noise_does_not_integrate_in_increment_mode(arch):
    """A network that predicts no increment must hold its output in a noisy training free run, not random-walk."""
    model = build_model(ModelConfig(arch=arch, n_u=1, n_y=1, hidden=4, increment=True)).double().train()
    with torch.no_grad():
        for p in model.parameters():
            p.zero_()
    model.feedback_noise = 0.5
    yn = model.rollout_normalised(torch.zeros(3, 400, 1, dtype=torch.float64), torch.ones(3, 1, dtype=torch.float64))
    assert torch.allclose(yn, torch.ones_like(yn))


def test_increment_mode_with_feedback_noise_trains_below_its_start_on_the_slider():
    from nnfmu.physics import generate_dataset

    ds = generate_dataset("slider", size="small", seed=0)
    result = train(ds, ModelConfig(arch="gru", n_u=1, n_y=1, hidden=16, increment=True),
                   TrainConfig(epochs=6, patience=0, truncate=200, batch_size=8, feedback_noise=0.1))
    assert result.best_epoch > 0 and result.best_valid_nrmse < result.history[0]["valid_nrmse"]
    assert all(np.isfinite(h["train_loss"]) and h["train_loss"] < 5.0 for h in result.history[1:])


def test_short_epochs_write_the_checkpoint_on_improvement_not_after_every_epoch(tmp_path, monkeypatch):
    from nnfmu.training import session

    writes = []
    real = session.save_checkpoint
    monkeypatch.setattr(session, "save_checkpoint", lambda *a, **k: (writes.append(1), real(*a, **k)))
    monkeypatch.setattr(session, "SAVE_EVERY_S", 3600.0)  # an improvement waits: only the first epoch and the end
    ds = one_record(300, 100)
    result = train(ds, ModelConfig(arch="mlp", n_u=1, n_y=1, hidden=4), TrainConfig(epochs=12, patience=0),
                   out=tmp_path / "m.pt")
    assert len(writes) <= 3 < len(result.history)
    from nnfmu.models import load_checkpoint

    ckpt = load_checkpoint(tmp_path / "m.pt")
    assert ckpt["resume"]["epoch"] == 12 and ckpt["best_epoch"] == result.best_epoch


def test_train_cli_starts_on_the_linear_path_says_its_plan_and_can_be_told_otherwise(tmp_path, capsys):
    from nnfmu.cli import main
    from nnfmu.data import save_dataset
    from nnfmu.linear import identify_linear
    from nnfmu.models import load_checkpoint
    from tests.test_linear import dataset, true_system

    ds = dataset(true_system(), noise=0.01)
    data = save_dataset(ds, tmp_path / "d")
    base = ["train", "--data", str(data), "--arch", "gru", "--hidden", "4", "--epochs", "2", "--quiet"]
    assert main([*base, "-o", str(tmp_path / "a.pt")]) == 0
    out = capsys.readouterr().out
    assert "plan: linear path of" in out and "plan: batch:" in out and "plan: budget:" in out
    assert load_checkpoint(tmp_path / "a.pt")["model_config"]["linear_order"] > 0
    assert main([*base, "--linear-path", "off", "-o", str(tmp_path / "b.pt")]) == 0
    assert load_checkpoint(tmp_path / "b.pt")["model_config"]["linear_order"] == 0
    saved = identify_linear(ds, order=3).save(tmp_path / "lin.json")
    assert main([*base, "--linear-path", str(saved), "-o", str(tmp_path / "c.pt")]) == 0
    assert load_checkpoint(tmp_path / "c.pt")["model_config"]["linear_order"] == 3
    capsys.readouterr()
    assert main([*base, "--linear-path", str(tmp_path / "none.json"), "-o", str(tmp_path / "d.pt")]) == 2
    assert "not found" in capsys.readouterr().err and not (tmp_path / "d.pt").exists()


def test_the_train_cli_says_join_no_join_or_nothing():
    """--join and --no-join reach the plan as given; neither leaves the choice to the plan."""
    from nnfmu.cli import build_parser

    base = ["train", "--data", "d", "--arch", "gru", "-o", "m.pt"]
    assert [build_parser().parse_args(base + extra).join for extra in ([], ["--join"], ["--no-join"])] == \
        [None, True, False]


def test_train_cli_at_its_defaults_trains_a_seed_per_core_and_keeps_them_by_validation_alone(tmp_path, capsys,
                                                                                               monkeypatch):
    """With the budget left to the plan and a core idle, one seed per core trains at once, and further waves while the
    plan's minutes allow (up to the most it trains); the kept model is the seed best on validation, joined by others
    only where their ensemble is 1 % better on validation (issue 38: never chosen on test); --seeds 1 and --epochs
    train one."""
    from nnfmu.cli import _train_plan, main
    from nnfmu.cli._train_plan import MAX_PLANNED_SEEDS, TrainRequest, planned_seeds, planned_waves
    from nnfmu.data import save_dataset
    from nnfmu.models import ModelConfig, load_checkpoint
    from nnfmu.training import resources

    at_defaults = TrainRequest(data="d", out=tmp_path / "b.pt", threads=1)  # `nnfmu train` at its defaults
    for cores, seeds in ((16, MAX_PLANNED_SEEDS), (5, 5), (2, 2), (1, None)):
        monkeypatch.setattr(resources, "usable_cores", lambda: cores)
        assert planned_seeds(at_defaults, ModelConfig(arch="gru", n_u=1, n_y=1), {}, None) == seeds
        # further waves within the plan's minutes, where there are fewer seeds than the most
        within = planned_waves(at_defaults, seeds, 10.0)
        assert within == (600.0 if seeds is not None and seeds < MAX_PLANNED_SEEDS else None)
    assert planned_waves(at_defaults.replace(seeds=2), 2, 10.0) is None  # --seeds K: K seeds
    capsys.readouterr()

    data = save_dataset(one_record(300, 100), tmp_path / "d")
    base = ["train", "--data", str(data), "--arch", "mlp", "--hidden", "4", "--patience", "1", "--quiet"]
    monkeypatch.setattr(resources, "usable_cores", lambda: 2)
    monkeypatch.setattr(_train_plan, "MAX_PLANNED_SEEDS", 4)  # two waves of two on this tiny record
    assert main([*base, "-o", str(tmp_path / "a.pt")]) == 0
    out = capsys.readouterr().out
    assert "plan: seeds: 2 trained side by side" in out and "then 2 more at a time" in out and "up to 4" in out
    assert "trained 4 seeds in 2 wave(s) of up to 2 side by side" in out
    assert "kept the ensemble of" in out or "alone (of 4 seeds):" in out  # what the checkpoint holds
    assert sorted(p.name for p in (tmp_path / "a.seeds").iterdir()) == [f"seed-{s}.pt" for s in range(4)]
    summary = load_checkpoint(tmp_path / "a.pt")["summary"]
    assert summary["keep"] == "select" and [r["seed"] for r in summary["seeds"]] == [0, 1, 2, 3]
    trained = [r for r in summary["seeds"] if r["best_epoch"] > 0] or summary["seeds"]
    best = min(r["best_valid_nrmse"] for r in trained)
    members = load_checkpoint(tmp_path / "a.pt")["model_config"]["members"]
    averaged = any("kept the ensemble of seeds" in n for n in summary["notes"])
    assert (members > 1) == averaged
    assert summary["best_valid_nrmse"] <= (0.99 * best if averaged else best) + 1e-9  # the margin, on validation
    assert summary["best_valid_nrmse"] <= min(r["start_valid_nrmse"] for r in summary["seeds"]) + 1e-9
    from nnfmu.cli.info import describe, render

    shown = " ".join(render(describe(tmp_path / "a.pt")).split())  # nnfmu info: each seed in a few words
    assert all(f"seed {r['seed']}: validation {r['best_valid_nrmse']:.4f}" in shown for r in summary["seeds"])
    for extra, name in ((["--seeds", "1"], "b"), (["--epochs", "3"], "c")):
        assert main([*base, *extra, "-o", str(tmp_path / f"{name}.pt")]) == 0
        assert "plan: seeds" not in capsys.readouterr().out and not (tmp_path / f"{name}.seeds").exists()
        assert "seeds" not in load_checkpoint(tmp_path / f"{name}.pt")["summary"]
    monkeypatch.setattr(resources, "usable_cores", lambda: 1)  # no idle core: one training
    assert main([*base, "-o", str(tmp_path / "d.pt")]) == 0
    assert "plan: seeds" not in capsys.readouterr().out and not (tmp_path / "d.seeds").exists()


def _running_with(text: str) -> list[int]:
    """PIDs of the processes whose command line holds ``text`` (Linux /proc)."""
    pids = []
    for cmdline in Path("/proc").glob("[0-9]*/cmdline"):
        try:
            if text.encode() in cmdline.read_bytes():
                pids.append(int(cmdline.parent.name))
        except OSError:
            pass
    return pids


@pytest.mark.skipif(not Path("/proc/self/cmdline").exists(), reason="reads /proc to find the seeds' processes")
@pytest.mark.skipif(usable_cores() < 2, reason="two seeds train at the defaults only with two cores")
def test_a_terminated_default_training_stops_its_seeds_and_keeps_them(tmp_path):
    """SIGTERM to `nnfmu train` reaches its two seed processes: they stop and keep their checkpoints (exit 143)."""
    import signal
    import subprocess
    import sys
    import time

    from nnfmu.data import save_dataset

    data = save_dataset(one_record(3000, 100), tmp_path / "d")
    out = tmp_path / "a.pt"
    proc = subprocess.Popen([sys.executable, "-m", "nnfmu", "train", "--data", str(data), "--arch", "mlp", "--hidden",
                             "4", "--quiet", "-o", str(out)], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    members = [tmp_path / "a.seeds" / f"seed-{s}.pt" for s in (0, 1)]
    deadline = time.monotonic() + 120
    while not all(m.exists() for m in members) and time.monotonic() < deadline and proc.poll() is None:
        time.sleep(0.2)
    assert proc.poll() is None, proc.communicate()  # still training: the budget is thousands of epochs
    proc.send_signal(signal.SIGTERM)
    stdout, stderr = proc.communicate(timeout=120)
    assert proc.returncode == 143 and "run the same command again to continue" in stdout, stderr
    assert not out.exists() and _running_with(str(tmp_path / "a.seeds")) == []
    from nnfmu.models import load_checkpoint

    kept = [load_checkpoint(m) for m in members]  # stopped by the signal, not trained to their end
    assert all("resume" in c and "stop_reason" not in (c.get("summary") or {}) for c in kept)


def test_validation_blocks_spread_over_one_record(tmp_path, capsys):
    """--valid-blocks K holds out --valid-fraction of one record as K blocks spread over it (blocked
    cross-validation's hold-out), not its tail; the training pieces are what lies between them, nothing lost."""
    from nnfmu.cli import main
    from nnfmu.data import save_dataset
    from nnfmu.errors import DataError
    from nnfmu.models import load_checkpoint
    from nnfmu.training import TrainConfig
    from nnfmu.training.trainer import prepare_dataset

    ds = one_record(2000, 200)
    carved, notes = prepare_dataset(ds, TrainConfig(valid_fraction=0.2, valid_blocks=4))
    assert list(carved.valid.lengths) == [100] * 4 and list(carved.train.lengths) == [400] * 4
    starts = [int(np.flatnonzero((ds.train.u[0] == v[0]).all(axis=1))[0]) for v in carved.valid.u]
    assert starts == [400, 900, 1400, 1900] and "4 blocks spread over the training record" in notes[0]
    assert carved.train.n_samples + carved.valid.n_samples == 2000  # every sample is in one split or the other
    tail, _ = prepare_dataset(ds, TrainConfig(valid_fraction=0.2))
    np.testing.assert_array_equal(tail.valid.u[0], ds.train.u[0][1600:])  # 1 block: the tail, as before
    with pytest.raises(DataError, match="fewer blocks"):
        ds.with_validation(0.2, blocks=1000)
    data = save_dataset(ds, tmp_path / "d")
    assert main(["train", "--data", str(data), "--arch", "mlp", "--hidden", "4", "--epochs", "2", "--quiet",
                 "--valid-fraction", "0.2", "--valid-blocks", "4", "-o", str(tmp_path / "m.pt")]) == 0
    assert "validating on 4 blocks spread over the training record, 20% of it" in capsys.readouterr().out
    saved = load_checkpoint(tmp_path / "m.pt")["train_config"]
    assert (saved["valid_fraction"], saved["valid_blocks"]) == (0.2, 4)
