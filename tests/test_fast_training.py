"""The speed paths of training compute what the plain torch paths compute.

- the compiled free run of the recurrent networks (nnfmu/training/rollout.c): values and
  gradients equal torch's in float64, for every cell, depth, width and skip setting;
- whole trainings with and without it give the same history;
- batches gathered from equal-length trajectories equal the sliced and stacked ones.
"""

from __future__ import annotations

import numpy as np
import pytest
import torch

from nnfmu.errors import FmuBuildError
from nnfmu.models import ModelConfig, build_model
from nnfmu.training import TrainConfig, train
from nnfmu.training import compiled_rollout as cr
from nnfmu.training.batches import _pad, _windows, epoch_batches
from nnfmu.training.evaluate import free_run
from nnfmu.training.rollout_library import library_or_none

pytestmark = pytest.mark.usefixtures("one_thread")

CASES = [  # arch, activation, layers, hidden, skip: widths below, at and between the C vector blocks
    ("gru", "tanh", 1, 8, True), ("gru", "tanh", 2, 21, False), ("gru", "tanh", 1, 40, True),
    ("lstm", "tanh", 2, 7, True), ("lstm", "tanh", 1, 33, False),
    ("rnn", "tanh", 1, 16, True), ("rnn", "relu", 2, 9, True),
]


def _model(arch, activation, layers, hidden, skip, dtype=torch.float64):
    torch.manual_seed(0)
    config = ModelConfig(arch=arch, n_u=3, n_y=2, hidden=hidden, layers=layers, activation=activation, skip=skip)
    return build_model(config).to(dtype)


def _inputs(batch: int, steps: int) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """Seeded normalised inputs (B, T, 3), initial outputs (B, 2) that take a gradient, and loss weights (B, T, 2)."""
    g = torch.Generator().manual_seed(1)
    un = torch.randn(batch, steps, 3, generator=g, dtype=torch.float64)
    yn0 = torch.randn(batch, 2, generator=g, dtype=torch.float64, requires_grad=True)
    return un, yn0, torch.randn(batch, steps, 2, generator=g, dtype=torch.float64)


@pytest.mark.parametrize("arch, activation, layers, hidden, skip", CASES)
def test_compiled_free_run_and_its_gradients_equal_torch_in_float64(arch, activation, layers, hidden, skip):
    model = _model(arch, activation, layers, hidden, skip)
    un, yn0, weight = _inputs(5, 60)
    rollout = cr.compiled_rollout(model)
    assert rollout is not None
    wanted, got = model.rollout_normalised(un, yn0), rollout(un, yn0)
    inputs = [yn0, *model.parameters()]
    grads_wanted = torch.autograd.grad((wanted * weight).sum(), inputs)
    grads_got = torch.autograd.grad((got * weight).sum(), inputs)
    scale = float(wanted.detach().abs().max())
    assert got.shape == wanted.shape and torch.allclose(got, wanted, rtol=0, atol=1e-12 * scale)
    for a, b in zip(grads_got, grads_wanted):
        assert torch.allclose(a, b, rtol=0, atol=1e-12 * float(b.abs().max()))


@pytest.mark.parametrize("arch", ["gru", "lstm", "rnn"])
def test_with_feedback_noise_the_compiled_free_run_adds_torch_s_draws(arch):
    """Noise on the fed-back output in training: the C code gets torch's own draws (one a step, in order), so
    values and gradients equal torch's loop for the same seed, and another seed gives other numbers."""
    model = _model(arch, "tanh", 2, 8, True).train()
    model.feedback_noise = 0.3
    un, yn0, weight = _inputs(4, 40)
    rollout = cr.compiled_rollout(model)
    assert rollout is not None
    torch.manual_seed(7)
    wanted = model.rollout_normalised(un, yn0)
    torch.manual_seed(7)
    got = rollout(un, yn0)
    torch.manual_seed(8)
    other = rollout(un, yn0)
    scale = float(wanted.detach().abs().max())
    assert torch.allclose(got, wanted, rtol=0, atol=1e-12 * scale)
    assert float((other - wanted).detach().abs().max()) > 1e-3 * scale  # the noise is there
    inputs = [yn0, *model.parameters()]
    for a, b in zip(torch.autograd.grad((got * weight).sum(), inputs), torch.autograd.grad((wanted * weight).sum(),
                                                                                             inputs)):
        assert torch.allclose(a, b, rtol=0, atol=1e-12 * float(b.abs().max()))


@pytest.mark.parametrize("option", ["increment", "init_window"])
def test_a_training_free_run_with_an_option_the_c_code_lacks_is_torch_s(option):
    """The issue-11 options (increment readout, encoder initial state) are computed by torch, not silently
    dropped by the compiled free run."""
    torch.manual_seed(0)
    config = ModelConfig(arch="gru", n_u=3, n_y=2, hidden=8, skip=True, increment=option == "increment",
                         init_window=4 if option == "init_window" else 1)
    model = build_model(config).double().train()
    g = torch.Generator().manual_seed(1)
    un, yn = torch.randn(5, 40, 3, generator=g, dtype=torch.float64), torch.randn(5, 40, 2, generator=g,
                                                                                 dtype=torch.float64)
    past = (yn[:, :3], un[:, :3]) if option == "init_window" else None
    torch.manual_seed(2)
    got = cr.training_rollout(model)(un[:, 3:], yn[:, 3:], past)
    torch.manual_seed(2)
    wanted = model.rollout_normalised(un[:, 3:], yn[:, 3, :], None, past)
    assert torch.equal(got, wanted)


def test_the_free_run_in_physical_units_takes_the_compiled_path_and_agrees(valve_small):
    model = build_model(ModelConfig(arch="gru", n_u=2, n_y=2, hidden=8), norm=valve_small.norm_stats("train"))
    test = valve_small.test
    fast = free_run(model, test, float64=True)
    with_torch = [model.simulate(u, y[0]) for u, y in zip(test.u, test.y)]
    for a, b in zip(fast, with_torch):
        np.testing.assert_allclose(a, b, rtol=1e-11, atol=1e-11 * np.abs(b).max())


def test_the_compiled_path_applies_only_where_it_computes_the_same():
    model = _model("gru", "tanh", 1, 8, True, torch.float32)
    assert cr.compiled_rollout(model) is not None
    dropout = build_model(ModelConfig(arch="lstm", n_u=3, n_y=2, hidden=8, dropout=0.2))
    assert cr.compiled_rollout(dropout.train()) is None  # dropout masks are drawn by torch
    assert cr.compiled_rollout(dropout.eval()) is not None
    assert cr.compiled_rollout(model.to(torch.float16)) is None


def test_without_a_c_compiler_training_runs_in_torch_with_a_warning(monkeypatch, valve_small):
    def no_compiler(*args, **kwargs):
        raise FmuBuildError("no C compiler found: looked for 'cc' (PATH)")

    monkeypatch.setattr("nnfmu.cbuild.compiler_argv", no_compiler)
    library_or_none.cache_clear()
    try:
        with pytest.warns(RuntimeWarning, match="torch instead of compiled C"):
            assert cr.compiled_rollout(_model("gru", "tanh", 1, 8, True)) is None
    finally:
        library_or_none.cache_clear()


@pytest.mark.parametrize("arch", ["gru", "lstm"])
def test_a_training_with_the_compiled_free_run_equals_one_in_torch(valve_small, monkeypatch, arch):
    data = valve_small.replace(splits={"train": valve_small.train.subset(range(8)), "test": valve_small.test})
    config = ModelConfig(arch=arch, n_u=2, n_y=2, hidden=8)
    options = TrainConfig(epochs=2, batch_size=4, truncate=50, dtype="float64", patience=0)
    fast = train(data, config, options)
    monkeypatch.setenv(cr.ENV_SWITCH, "0")
    plain = train(data, config, options)
    assert len(fast.history) == len(plain.history) == 3
    for a, b in zip(fast.history[1:], plain.history[1:]):
        assert a["valid_nrmse"] == pytest.approx(b["valid_nrmse"], rel=1e-9)
        assert a["train_loss"] == pytest.approx(b["train_loss"], rel=1e-9)
    assert fast.test_nrmse == pytest.approx(plain.test_nrmse, rel=1e-9)


@pytest.mark.parametrize("truncate", [None, 50, 7, 200])
def test_gathered_batches_equal_the_sliced_ones(truncate):
    g = torch.Generator().manual_seed(0)
    seqs = [(torch.randn(200, 2, generator=g), torch.randn(200, 3, generator=g)) for _ in range(23)]
    fast = list(epoch_batches(seqs, batch_size=5, truncate=truncate, generator=torch.Generator().manual_seed(4)))
    generator = torch.Generator().manual_seed(4)
    items = seqs if truncate is None else _windows(seqs, truncate, generator)
    order = torch.randperm(len(items), generator=generator).tolist()
    sliced = [_pad([items[i] for i in order[at:at + 5]]) for at in range(0, len(order), 5)]
    assert len(fast) == len(sliced) > 1
    for a, b in zip(fast, sliced):
        assert torch.equal(a.un, b.un) and torch.equal(a.yn, b.yn) and a.mask is None and b.mask is None


def test_trajectories_of_different_lengths_are_still_padded_and_masked():
    seqs = [(torch.zeros(n, 1), torch.zeros(n, 1)) for n in (30, 20, 30)]
    batches = list(epoch_batches(seqs, batch_size=3, truncate=None, generator=torch.Generator().manual_seed(0)))
    assert len(batches) == 1 and batches[0].mask is not None and int(batches[0].mask.sum()) == 80

