"""The one trainer, both strategies, all five architectures, on small generated valve data."""

from __future__ import annotations

import os
import signal

import numpy as np
import pytest
import torch

from nnfmu.data import Dataset, Trajectories, from_arrays
from nnfmu.errors import ConfigError, DataError, TrainingError, UnknownOptionError
from nnfmu.models import ModelConfig, build_model, load_checkpoint, load_model
from nnfmu.training import STRATEGIES, StopTraining, TrainConfig, train
from nnfmu.training.batches import Batch, epoch_batches, masked_mse
from builtin_networks import ARCHS

TINY = dict(hidden=8)
FAST = dict(epochs=3, batch_size=8, truncate=40, lr=1e-2, patience=0)


pytestmark = pytest.mark.usefixtures("one_thread")


@pytest.fixture(scope="module")
def valve_tiny(valve_small) -> Dataset:
    """12 training trajectories and one shortened test trajectory of the small valve data."""
    train_split, test_split = valve_small.train, valve_small.test
    test_split = Trajectories((test_split.u[0][:400],), (test_split.y[0][:400],))
    return valve_small.replace(splits={"train": train_split.subset(range(12)), "test": test_split})


@pytest.fixture(scope="module")
def trained(valve_tiny, tmp_path_factory):
    """One short training per (arch, strategy), made on first use and shared by the tests."""
    cache = {}

    def get(arch: str, strategy: str):
        if (arch, strategy) not in cache:
            out = tmp_path_factory.mktemp("ckpt") / f"{arch}-{strategy}.pt"
            config = ModelConfig(arch=arch, n_u=2, n_y=2, **TINY)
            cache[arch, strategy] = train(valve_tiny, config, TrainConfig(strategy=strategy, **FAST), out=out)
        return cache[arch, strategy]

    return get


ALL = [(a, s) for a in ARCHS for s in STRATEGIES]


@pytest.mark.parametrize("arch, strategy", ALL)
def test_short_training_lowers_validation_free_run_nrmse(trained, arch, strategy):
    result = trained(arch, strategy)
    initial = result.history[0]["valid_nrmse"]
    assert [h["epoch"] for h in result.history] == [0, 1, 2, 3]
    assert result.best_valid_nrmse < 0.8 * initial
    assert result.best_epoch > 0 and result.stop_reason == "epochs"
    assert np.isfinite(result.test_nrmse) and result.test.per_output.shape == (1, 2)
    assert any("no 'valid' split" in note for note in result.notes)


@pytest.mark.parametrize("arch, strategy", ALL)
def test_training_is_deterministic_with_a_seed(trained, valve_tiny, arch, strategy):
    first = trained(arch, strategy)
    again = train(valve_tiny, ModelConfig(arch=arch, n_u=2, n_y=2, **TINY), TrainConfig(strategy=strategy, **FAST))
    for key, value in first.model.state_dict().items():
        assert torch.equal(value, again.model.state_dict()[key]), key
    assert [h["valid_nrmse"] for h in first.history] == [h["valid_nrmse"] for h in again.history]


@pytest.mark.parametrize("arch, strategy", ALL)
def test_checkpoint_of_a_training_round_trips(trained, valve_tiny, arch, strategy):
    result = trained(arch, strategy)
    raw = torch.load(result.checkpoint, weights_only=True)
    assert raw["best_epoch"] == result.best_epoch and len(raw["history"]) == len(result.history)
    assert raw["meta"]["Ts"] == valve_tiny.Ts and raw["meta"]["outputs"][1]["unit"] == "Pa"
    assert raw["train_config"]["strategy"] == strategy
    assert raw["summary"]["test_nrmse"] == pytest.approx(result.test_nrmse)
    loaded = load_model(result.checkpoint)
    u, y = valve_tiny.test.u[0], valve_tiny.test.y[0]
    np.testing.assert_array_equal(loaded.simulate(u, y[0]), result.model.simulate(u, y[0]))


def test_resume_continues_exactly_like_an_uninterrupted_run(valve_tiny, tmp_path):
    config = ModelConfig(arch="gru", n_u=2, n_y=2, hidden=8, dropout=0.1)
    full = train(valve_tiny, config, TrainConfig(**{**FAST, "epochs": 4}))
    out = tmp_path / "gru.pt"
    first = train(valve_tiny, config, TrainConfig(**{**FAST, "epochs": 2}), out=out)
    assert first.stop_reason == "epochs" and load_checkpoint(out)["resume"]["epoch"] == 2
    resumed = train(valve_tiny, None, TrainConfig(**{**FAST, "epochs": 4}), out=out, resume=True)
    assert [h["valid_nrmse"] for h in resumed.history] == [h["valid_nrmse"] for h in full.history]
    for key, value in full.model.state_dict().items():
        assert torch.equal(value, resumed.model.state_dict()[key]), key


def test_sigint_keeps_the_best_checkpoint_and_resume_finishes(valve_tiny, tmp_path):
    out = tmp_path / "mlp.pt"
    config = ModelConfig(arch="mlp", n_u=2, n_y=2, **TINY)

    def interrupt_after_epoch_2(epoch, metrics):
        if epoch == 2:
            os.kill(os.getpid(), signal.SIGINT)  # like Ctrl-C while epoch 3 runs

    before = signal.getsignal(signal.SIGINT)  # Python's default, or one an earlier test's Ray Tune left
    result = train(valve_tiny, config, TrainConfig(**{**FAST, "epochs": 5}), out=out,
                   callback=interrupt_after_epoch_2)
    assert result.stop_reason == "SIGINT" and result.test is None
    ckpt = load_checkpoint(out)
    assert ckpt["resume"]["epoch"] == 2 and ckpt["best_epoch"] == result.best_epoch <= 2
    assert signal.getsignal(signal.SIGINT) is before  # the handler there before is restored
    resumed = train(valve_tiny, config, None, out=out, resume=True)
    assert resumed.stop_reason == "epochs" and [h["epoch"] for h in resumed.history] == list(range(6))


def test_callback_sees_every_epoch_and_can_stop(valve_tiny):
    seen = []

    def callback(epoch, metrics):
        seen.append((epoch, set(metrics)))
        if epoch == 2:
            raise StopTraining

    result = train(valve_tiny, ModelConfig(arch="tcn", n_u=2, n_y=2, layers=2, **TINY),
                   TrainConfig(**{**FAST, "epochs": 10}), callback=callback)
    assert [e for e, _ in seen] == [1, 2] and result.stop_reason == "callback"
    assert {"train_loss", "valid_nrmse", "best_valid_nrmse"} <= seen[0][1]


def test_time_budget_ends_training_with_a_validated_partial_epoch(valve_tiny):
    result = train(valve_tiny, ModelConfig(arch="gru", n_u=2, n_y=2, **TINY),
                   TrainConfig(**{**FAST, "epochs": 50, "batch_size": 1, "max_minutes": 1e-4}))
    assert result.stop_reason == "time-budget"
    assert result.history[-1]["partial"] and len(result.history) == 2


def test_early_stopping_after_patience_epochs_without_progress(valve_tiny, monkeypatch):
    scripted = iter([1.0, 0.9, 0.95, 0.97, 0.5, 0.4])  # epoch 0, 1, 2, 3, ...
    monkeypatch.setattr("nnfmu.training.session.score", lambda model, traj, **kw: next(scripted))
    result = train(valve_tiny, ModelConfig(arch="mlp", n_u=2, n_y=2, **TINY),
                   TrainConfig(**{**FAST, "epochs": 30, "patience": 2}))
    assert result.stop_reason == "early-stopping" and len(result.history) == 4
    assert result.best_epoch == 1 and result.best_valid_nrmse == 0.9
    assert [h["improved"] for h in result.history] == [True, True, False, False]


def test_nan_in_the_data_gives_a_clear_error(valve_tiny):
    u, y = np.stack(valve_tiny.train.u[:2]), np.stack(valve_tiny.train.y[:2])
    y[1, 7, 0] = np.nan
    with pytest.raises(DataError, match=r"train trajectory 1: array 'y' has 1 non-finite value.*step 7"):
        from_arrays(Ts=4e-5, u_train=u, y_train=y, u_test=u, y_test=y)
    huge = valve_tiny.replace(splits={**valve_tiny.splits, "train": Trajectories(
        valve_tiny.train.u[:3], tuple(y * 1e40 for y in valve_tiny.train.y[:3]))})  # fine in float64 only
    with pytest.raises(DataError, match="non-finite values after normalisation.*train in float64"):
        train(huge, ModelConfig(arch="gru", n_u=2, n_y=2, **TINY), TrainConfig(**FAST))


def test_nan_loss_raises_training_error_with_advice(valve_tiny):
    model = build_model(ModelConfig(arch="gru", n_u=2, n_y=2, **TINY))
    with torch.no_grad():
        model.readout.weight.fill_(float("nan"))
    with pytest.raises(TrainingError, match=r"loss became nan.*epoch 1, batch 1; lower the learning rate"):
        train(valve_tiny, model, TrainConfig(**FAST))


def test_trajectories_of_different_lengths_train_without_padding_in_the_loss(valve_tiny):
    tr = valve_tiny.train
    ragged = Trajectories(tuple(u[:300 - 20 * i] for i, u in enumerate(tr.u)),
                          tuple(y[:300 - 20 * i] for i, y in enumerate(tr.y)))
    data = valve_tiny.replace(splits={**valve_tiny.splits, "train": ragged})
    result = train(data, ModelConfig(arch="lstm", n_u=2, n_y=2, **TINY), TrainConfig(**{**FAST, "truncate": None}))
    assert result.best_valid_nrmse < result.history[0]["valid_nrmse"]
    # the masked loss of a padded batch is the mean over the real samples only
    seqs = [(torch.randn(n, 2), torch.randn(n, 2)) for n in (5, 9)]
    batch = next(epoch_batches(seqs, batch_size=2, truncate=None, generator=torch.Generator().manual_seed(0)))
    assert batch.mask is not None and batch.un.shape == (2, 9, 2)
    pred = batch.yn + 1.0
    pred[batch.mask.logical_not()] = 1e6  # anything in the padding must not count
    assert masked_mse(pred, batch.yn, batch.mask).item() == pytest.approx(1.0)


def test_masked_mse_skips_the_given_first_sample():
    yn = torch.zeros(1, 4, 1)
    pred = torch.tensor([[[5.0], [1.0], [1.0], [1.0]]])
    assert masked_mse(pred, yn, None).item() == 1.0
    assert isinstance(Batch(yn, yn, None), Batch)


def test_train_options_are_checked(valve_tiny):
    with pytest.raises(ConfigError, match="unknown strategy 'serial'; choose one of parallel, series-parallel"):
        TrainConfig(strategy="serial")
    with pytest.raises(UnknownOptionError, match="'epoch'.*valid options are"):
        TrainConfig.from_dict({"epoch": 3})
    with pytest.raises(ConfigError, match="truncate must be None or an integer >= 2"):
        TrainConfig(truncate=1)
    with pytest.raises(ConfigError, match="model config has n_u=3, n_y=2 but the dataset has 2 inputs"):
        train(valve_tiny, ModelConfig(arch="gru", n_u=3, n_y=2), TrainConfig(**FAST))
    with pytest.raises(ConfigError, match="resume=True needs out"):
        train(valve_tiny, None, resume=True)
