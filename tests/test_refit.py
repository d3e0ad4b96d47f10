"""The refit (:mod:`nnfmu.training.refit`): the kept seeds trained once more on the training and validation data."""

from __future__ import annotations

import pytest
import torch

from nnfmu.errors import ConfigError
from nnfmu.models import EnsembleStepModel, ModelConfig, load_checkpoint
from nnfmu.training import TrainConfig, train, train_seeds
from nnfmu.training.refit import refit_dataset, training_and_validation
from tests.test_training import FAST, TINY

pytestmark = pytest.mark.usefixtures("one_thread")


def gru() -> ModelConfig:
    return ModelConfig(arch="gru", n_u=2, n_y=2, **TINY)


def _same_weights(a, b) -> bool:
    sa, sb = a.state_dict(), b.state_dict()
    return sa.keys() == sb.keys() and all(torch.equal(sa[k], sb[k]) for k in sa)


def test_keep_weights_last_keeps_the_last_epoch_even_where_validation_was_better_before(valve_tiny):
    cfg = TrainConfig(**{**FAST, "epochs": 4, "patience": 0, "lr": 0.05})
    best, last = train(valve_tiny, gru(), cfg), train(valve_tiny, gru(), cfg.replace(keep_weights="last"))
    assert last.best_epoch == 4 and last.best_valid_nrmse == last.history[-1]["valid_nrmse"]
    assert best.best_valid_nrmse == min(h["valid_nrmse"] for h in best.history)
    if best.best_epoch != 4:  # the runs are the same until then; only what is kept differs
        assert not _same_weights(best.model, last.model)


def test_the_refit_is_each_kept_seed_trained_again_on_training_and_validation_data_for_its_epochs(valve_tiny,
                                                                                                    tmp_path):
    cfg = TrainConfig(**{**FAST, "epochs": 3})
    whole = training_and_validation(valve_tiny)
    assert whole.n_traj == 12 and whole.n_samples == valve_tiny.train.n_samples + valve_tiny.valid.n_samples
    out = tmp_path / "r.pt"
    result = train_seeds(valve_tiny, gru(), cfg, seeds=2, keep="best", out=out, jobs=1, refit_on=whole)
    chosen = min(result.seeds, key=lambda r: r["best_valid_nrmse"])
    assert result.refit["seeds"] == [chosen["seed"]] and result.refit["epochs"] == [chosen["best_epoch"]]
    assert result.refit["train_samples"] == whole.n_samples
    # the validation score reported is the one the model was chosen by: the refit has seen the validation data
    assert result.valid_nrmse == chosen["best_valid_nrmse"]
    assert result.refit["chosen_test_nrmse"] == pytest.approx(chosen["test_nrmse"], rel=1e-9)
    # the same network from the same seed, trained on all of it for the chosen epochs, landing on the moving average
    # of its weights
    again = train(refit_dataset(valve_tiny, whole), gru(), cfg.replace(
        seed=chosen["seed"], epochs=chosen["best_epoch"], patience=0, keep_weights="last", average="ema"))
    assert _same_weights(result.model, again.model)
    assert result.test_nrmse == pytest.approx(again.test_nrmse, rel=1e-9)
    refit_file = tmp_path / "r.seeds" / f"refit-{chosen['seed']}.pt"
    stamp = refit_file.stat().st_mtime_ns
    kept = train_seeds(valve_tiny, gru(), cfg, seeds=2, keep="best", out=out, jobs=1, refit_on=whole)
    assert refit_file.stat().st_mtime_ns == stamp and _same_weights(kept.model, result.model)  # not trained again
    assert load_checkpoint(out)["summary"]["refit"]["seeds"] == [chosen["seed"]]


def test_an_ensemble_is_rebuilt_from_its_seeds_refits(valve_tiny, tmp_path):
    cfg = TrainConfig(**{**FAST, "epochs": 2})
    result = train_seeds(valve_tiny, gru(), cfg, seeds=2, keep="ensemble", out=tmp_path / "e.pt", jobs=2,
                         refit_on=training_and_validation(valve_tiny))
    trained = [r["seed"] for r in result.seeds if r["best_epoch"]]
    assert result.refit["seeds"] == trained
    if len(trained) == 2:
        assert isinstance(result.model, EnsembleStepModel)
        for member, seed in zip(result.model.members, trained):
            refit = load_checkpoint(tmp_path / "e.seeds" / f"refit-{seed}.pt")
            assert all(torch.equal(member.state_dict()[k], v) for k, v in refit["state_dict"].items())


def test_a_schedule_that_follows_validation_is_not_refitted_and_says_so(valve_tiny, tmp_path):
    cfg = TrainConfig(**{**FAST, "epochs": 2, "lr_schedule": "plateau"})
    result = train_seeds(valve_tiny, gru(), cfg, seeds=2, keep="best", out=tmp_path / "p.pt", jobs=1,
                         refit_on=training_and_validation(valve_tiny))
    assert result.refit is None and any(n.startswith("no refit: the learning-rate schedule") for n in result.notes)
    assert not list((tmp_path / "p.seeds").glob("refit-*.pt"))


def test_nnfmu_train_refits_its_kept_seeds_on_request_and_refuses_where_there_are_none(tmp_path, capsys):
    from fmu_cases import oscillator_dataset

    from nnfmu.cli import main

    data, out = oscillator_dataset(tmp_path / "data"), tmp_path / "m.pt"
    base = ["train", "--data", str(data), "--arch", "gru", "--hidden", "4", "--epochs", "2", "--linear-path", "off",
            "--quiet", "-o", str(out)]
    assert main(base + ["--refit"]) == 2  # one training: no seeds to refit
    assert "--refit refits the seeds that a run of several seeds keeps: add --seeds K" in capsys.readouterr().err
    assert not out.exists() and not (tmp_path / "m.seeds").exists()
    assert main(base + ["--seeds", "2", "--refit", "--jobs", "1"]) == 0
    printed = capsys.readouterr().out
    assert "plan: refit: after choosing on validation, the kept seeds train once more on the training and " in printed
    assert "note: refitted on the training and validation data together (180 samples" in printed
    summary = load_checkpoint(out)["summary"]
    assert summary["refit"]["seeds"] and all((tmp_path / "m.seeds" / f"refit-{s}.pt").exists()
                                             for s in summary["refit"]["seeds"])


def test_seeds_written_before_the_refit_existed_are_taken_as_finished_not_as_other_settings(valve_tiny, tmp_path):
    from nnfmu.training.seed_runs import member_state

    cfg = TrainConfig(**{**FAST, "epochs": 1})
    path = tmp_path / "seed-0.pt"
    train(valve_tiny, gru(), cfg, out=path)
    ckpt = load_checkpoint(path)
    del ckpt["train_config"]["keep_weights"]  # as written before TrainConfig had it
    torch.save(ckpt, path)
    assert member_state(path, gru(), cfg) == "finished"
    with pytest.raises(ConfigError, match="other settings"):
        member_state(path, gru(), cfg.replace(keep_weights="last"))


def test_the_plan_refits_on_the_record_as_loaded_not_on_its_carved_pieces(tmp_path, capsys):
    """One training record: the validation tail is cut from it for choosing, and the refit trains on it whole."""
    import numpy as np

    from nnfmu.cli._train_plan import TrainRequest, make_plan
    from nnfmu.data import from_arrays, save_dataset

    rng = np.random.default_rng(0)
    u = rng.normal(size=(500, 1))
    y = np.cumsum(u, axis=0) * 0.01
    data = save_dataset(from_arrays(Ts=0.1, u_train=[u[:400]], y_train=[y[:400]], u_test=[u[400:]],
                                    y_test=[y[400:]]), tmp_path / "d")
    plan = make_plan(TrainRequest(data=str(data), out=tmp_path / "m.pt", arch="gru", seeds=2, refit=True,
                                  linear_path="off"))
    assert plan.data.train.n_samples < 400 and plan.data.valid is not None  # chosen on the carved head
    assert plan.refit_on.n_traj == 1 and np.array_equal(plan.refit_on.y[0], y[:400])
    assert "plan: refit: after choosing on validation" in capsys.readouterr().out
