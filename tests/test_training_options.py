"""What is trained: feedback noise, weight averaging, LR schedule, joined records, validation horizon,
init-window training, and K seeds (best or ensemble)."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from nnfmu.errors import ConfigError
from nnfmu.models import EnsembleStepModel, ModelConfig, load_checkpoint, load_model
from nnfmu.training import TrainConfig, train, train_seeds
from nnfmu.training.averaging import WeightAverage
from nnfmu.training.evaluate import score
from nnfmu.training.horizons import join_sequences, lr_factor, validation_trajectories
from tests.test_training import FAST, TINY

pytestmark = pytest.mark.usefixtures("one_thread")


def gru(**options) -> ModelConfig:
    return ModelConfig(arch="gru", n_u=2, n_y=2, **{**TINY, **options})


def test_feedback_noise_disturbs_training_free_runs_only():
    from tests.test_models import make_model, random_io

    model = make_model("gru")
    u, y = random_io(2, 30)
    model.feedback_noise = 0.1
    with torch.no_grad():
        model.train()
        assert not torch.equal(model(u, y[:, 0]), model(u, y[:, 0]))  # fresh noise every run
        model.eval()
        assert torch.equal(model(u, y[:, 0]), model(u, y[:, 0]))


def test_weight_average_is_an_ema_per_step_and_a_mean_per_epoch():
    net = torch.nn.Linear(1, 1, bias=False)
    with torch.no_grad():
        net.weight.fill_(0.0)
    ema = WeightAverage(net, TrainConfig(average="ema", average_decay=0.5))
    swa = WeightAverage(net, TrainConfig(average="swa", epochs=4, average_start=0.5))
    expected = 0.0
    for step, value in enumerate((1.0, 2.0, 3.0, 4.0), start=1):
        with torch.no_grad():
            net.weight.fill_(value)
        decay = min(0.5, (1 + step) / (10 + step))  # a short memory while the average warms up
        expected = decay * expected + (1 - decay) * value
        ema.after_step()
        swa.after_epoch(step)
    assert ema.params["weight"].item() == pytest.approx(expected)
    assert swa.params["weight"].item() == pytest.approx(3.0)  # the mean of epochs 2..4 of 4
    with swa.applied():
        assert net.weight.item() == pytest.approx(3.0)
    assert net.weight.item() == 4.0  # the live weights are back


@pytest.mark.parametrize("average", ["ema", "swa"])
def test_validation_and_the_kept_weights_are_the_averaged_ones(valve_tiny, average):
    result = train(valve_tiny, gru(), TrainConfig(**{**FAST, "epochs": 4, "average": average}))
    assert score(result.model, valve_tiny.valid) == pytest.approx(result.best_valid_nrmse, rel=1e-6)


def test_cosine_schedule_ends_at_lr_final(valve_tiny, tmp_path):
    cfg = TrainConfig(**{**FAST, "lr_schedule": "cosine", "lr_final": 0.1})
    assert [lr_factor(cfg, p) for p in (0.0, 0.5, 1.0)] == pytest.approx([1.0, 0.55, 0.1])
    train(valve_tiny, gru(), cfg, out=tmp_path / "m.pt")
    last = load_checkpoint(tmp_path / "m.pt")["resume"]["optimizer"]["param_groups"][0]["lr"]
    assert cfg.lr * 0.1 < last < cfg.lr * 0.11  # the last batch of the last epoch


def test_plateau_lowers_the_rate_after_a_quarter_of_the_patience_and_goes_on_from_the_best_weights():
    from tests.test_models import make_model

    from nnfmu.training.session import Session

    model = make_model("gru")
    session = Session(model, TrainConfig(lr_schedule="plateau", patience=8, lr_final=0.05), [], None, None)
    session.record(None, 1.0, 0.0, False)  # epoch 0: the best so far
    best = {k: v.clone() for k, v in model.state_dict().items()}
    factors = []
    for epoch, score_ in enumerate((2.0, 3.0, 0.9, 1.5, 1.5, 1.5, 1.5, 1.5, 1.5, 1.5, 1.5), start=1):
        with torch.no_grad():  # the epoch's training moved the weights
            for p in model.parameters():
                p.add_(0.1)
        if score_ < 1.0:
            best = {k: v.clone() for k, v in model.state_dict().items()}
        session.epoch = epoch
        entry = session.record(0.0, score_, 0.0, False)
        factors.append(entry["lr_factor"])
        if entry["lr_decayed"]:  # back at the best weights, from which the smaller rate goes on
            assert all(torch.equal(model.state_dict()[k], v) for k, v in best.items())
    # 8 // 4 = 2 epochs without a better score, then x0.3; floored at lr_final; none after the patience is out
    assert factors == pytest.approx([1, 0.3, 0.3, 0.3, 0.09, 0.09, 0.05, 0.05, 0.05, 0.05, 0.05])
    assert session.patience_exhausted() and session.resume_state()["lr_level"] == pytest.approx(0.05)


def test_plateau_rate_is_the_optimisers_and_survives_a_resume(valve_tiny, tmp_path):
    cfg = TrainConfig(**{**FAST, "epochs": 12, "patience": 4, "lr_schedule": "plateau"})
    out = tmp_path / "m.pt"
    train(valve_tiny, gru(), cfg, out=out)
    ckpt = load_checkpoint(out)
    levels = [e["lr_factor"] for e in ckpt["history"][1:]]
    assert ckpt["resume"]["optimizer"]["param_groups"][0]["lr"] == pytest.approx(cfg.lr * levels[-2])
    assert ckpt["resume"]["lr_level"] == levels[-1]
    resumed = train(valve_tiny, gru(), cfg.replace(epochs=14), out=out, resume=True)
    assert [e["lr_factor"] for e in resumed.history[1:13]] == levels


def test_anneal_goes_on_from_the_best_weights_at_a_tenth_of_the_rate_when_the_patience_runs_out(valve_tiny, tmp_path):
    base = TrainConfig(**{**FAST, "epochs": 200, "patience": 4})
    constant = train(valve_tiny, gru(), base)
    annealed = train(valve_tiny, gru(), base.replace(lr_schedule="anneal"), out=tmp_path / "m.pt")
    stop = len(constant.history)  # the constant stage is the constant schedule's run, epoch for epoch
    assert [e["valid_nrmse"] for e in annealed.history[:stop]] == [e["valid_nrmse"] for e in constant.history]
    assert annealed.best_valid_nrmse <= constant.best_valid_nrmse  # never worse on validation
    factors = [e["lr_factor"] for e in annealed.history]
    stages = [f for before, f in zip([None] + factors, factors) if f != before]
    assert stages == pytest.approx([1.0, 0.1, 0.01])  # then lr_final ends it
    assert factors.index(stages[1]) == stop
    assert annealed.stop_reason == "early-stopping"


@pytest.mark.parametrize("schedule", ["plateau", "anneal"])
def test_without_a_patience_the_schedules_that_follow_validation_keep_the_rate_and_say_so(valve_tiny, schedule):
    result = train(valve_tiny, gru(), TrainConfig(**{**FAST, "lr_schedule": schedule, "patience": 0}))
    constant = train(valve_tiny, gru(), TrainConfig(**{**FAST, "patience": 0}))
    assert [e["valid_nrmse"] for e in result.history] == [e["valid_nrmse"] for e in constant.history]
    assert any("stays constant" in note and "--patience" in note for note in result.notes)


def test_joined_records_and_validation_horizon(valve_tiny):
    seqs = [(torch.ones(3, 2) * i, torch.ones(3, 1) * i) for i in range(3)]
    (u, y), = join_sequences(seqs)
    assert u.shape == (9, 2) and y[:, 0].tolist() == [0, 0, 0, 1, 1, 1, 2, 2, 2]
    split, notes = validation_trajectories(valve_tiny, TrainConfig())
    assert split.n_traj == 2 and not any("joined" in n for n in notes)  # not contiguous: kept apart
    contiguous = valve_tiny.replace(source={**valve_tiny.source, "contiguous": True},
                                    splits={**valve_tiny.splits, "test": valve_tiny.valid.concatenated()})
    joined, notes = validation_trajectories(contiguous, TrainConfig())
    assert joined.n_traj == 1 and joined.n_samples == valve_tiny.valid.n_samples and "joined" in notes[0]
    long_test = valve_tiny.replace(splits={**valve_tiny.splits, "test": valve_tiny.train.concatenated()})
    _, notes = validation_trajectories(long_test, TrainConfig(valid_horizon="split"))
    assert any(n.startswith("WARNING: the validation free runs cover at most 300 samples") for n in notes)
    result = train(valve_tiny, gru(), TrainConfig(**{**FAST, "join": True, "truncate": 500, "epochs": 1}))
    assert math.isfinite(result.best_valid_nrmse)  # windows of 500 span two 300-sample trajectories


def test_init_window_training_scores_both_ways(valve_tiny, tmp_path):
    result = train(valve_tiny, gru(init_window=8), TrainConfig(**FAST), out=tmp_path / "w.pt")
    assert result.test is not None and result.test_window is not None
    assert result.best_valid_nrmse == pytest.approx(score(result.model, valve_tiny.valid, context=8), rel=1e-6)
    summary = load_checkpoint(tmp_path / "w.pt")["summary"]
    assert summary["test_nrmse_window"] == pytest.approx(result.test_window.mean)
    model = load_model(tmp_path / "w.pt")
    u, y = valve_tiny.test.u[0], valve_tiny.test.y[0]
    assert model.simulate(u[7:], y[7], y_past=y[:7], u_past=u[:7]).shape == (len(u) - 7, 2)


def test_seeds_keep_the_best_or_their_ensemble_and_resume(valve_tiny, tmp_path):
    cfg = TrainConfig(**{**FAST, "epochs": 2})
    ens = train_seeds(valve_tiny, gru(), cfg, seeds=2, keep="ensemble", out=tmp_path / "e.pt", jobs=2)
    assert isinstance(ens.model, EnsembleStepModel) and [r["seed"] for r in ens.seeds] == [0, 1]
    tests = [r["test_nrmse"] for r in ens.seeds]
    assert ens.spread() == pytest.approx({"mean": np.mean(tests), "min": min(tests), "max": max(tests)})
    single = train(valve_tiny, gru(), cfg)  # seed 0 in a process of its own gives the same network
    assert tests[0] == pytest.approx(single.test_nrmse, rel=1e-6)
    members = [tmp_path / "e.seeds" / f"seed-{s}.pt" for s in (0, 1)]
    stamps = [p.stat().st_mtime_ns for p in members]
    best = train_seeds(valve_tiny, gru(), cfg, seeds=2, keep="best", out=tmp_path / "e.pt", jobs=1)
    assert [p.stat().st_mtime_ns for p in members] == stamps  # finished seeds are not trained again
    chosen = min(ens.seeds, key=lambda r: r["best_valid_nrmse"])
    assert best.test_nrmse == pytest.approx(chosen["test_nrmse"]) and best.model.config.members == 1
    # the selection averages the seeds only where that lowers the validation NRMSE by 1 %
    picked = train_seeds(valve_tiny, gru(), cfg, seeds=2, keep="select", out=tmp_path / "e.pt", jobs=1)
    averaged = ens.valid_nrmse <= 0.99 * chosen["best_valid_nrmse"] and isinstance(ens.model, EnsembleStepModel)
    assert picked.valid_nrmse == pytest.approx(ens.valid_nrmse if averaged else chosen["best_valid_nrmse"], rel=1e-5)
    assert isinstance(picked.model, EnsembleStepModel) == averaged
    assert any(n.startswith("kept seed" if not averaged else "kept the ensemble of seeds") for n in picked.notes)
    with pytest.raises(ConfigError, match="other settings"):
        train_seeds(valve_tiny, gru(hidden=4), cfg, seeds=2, out=tmp_path / "e.pt")
    narrow = train_seeds(valve_tiny, gru(hidden=4), cfg, seeds=2, out=tmp_path / "e.pt", jobs=1, overwrite=True)
    assert all(load_checkpoint(p)["model_config"]["hidden"] == 4 for p in members)  # --force: trained anew
    assert narrow.model.config.hidden == 4
    with pytest.raises(ConfigError, match="seeds must be an integer >= 2"):
        train_seeds(valve_tiny, gru(), cfg, seeds=1, out=tmp_path / "x.pt")


def test_increment_auto_keeps_the_output_mode_with_the_lower_validation_nrmse(valve_small_dir, tmp_path, capsys):
    from nnfmu.cli import main

    out = tmp_path / "m.pt"
    assert main(["train", "--data", str(valve_small_dir), "--arch", "mlp", "--hidden", "8", "--epochs", "1",
                 "--truncate", "40", "--increment", "auto", "--quiet", "-o", str(out)]) == 0
    scores = {m: load_checkpoint(tmp_path / f"m.{m}.pt")["summary"]["best_valid_nrmse"]
              for m in ("residual", "increment")}
    kept = load_checkpoint(out)
    assert kept["summary"]["best_valid_nrmse"] == min(scores.values())
    assert kept["model_config"]["increment"] == (scores["increment"] < scores["residual"])
    assert "kept the" in capsys.readouterr().out
