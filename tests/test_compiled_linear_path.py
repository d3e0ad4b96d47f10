"""The compiled free run (nnfmu/training/rollout.c) of a recurrent network on a linear path computes what torch's
generic loop over ``LinearPathStepModel.step_norm`` computes: outputs and the gradients of every parameter and
of ``yn0`` (through the network, the path and ``z0``), in float64, for every cell and depth; and a training on the
path with the compiled free run (recurrent, TCN and MLP: window_rollout.c) equals one in torch."""

from __future__ import annotations

import pytest
import torch

from nnfmu.models import ModelConfig, build_model
from nnfmu.training import TrainConfig, train
from nnfmu.training import compiled_rollout as cr
from tests.test_linear_path import data, linear, path_model  # noqa: F401 (module fixtures)

pytestmark = pytest.mark.usefixtures("one_thread")


def corrected(model):
    """``model`` with a correction that is not zero: G, alpha and the readout all reach the output."""
    g = torch.Generator().manual_seed(3)
    with torch.no_grad():
        model.alpha.copy_(0.5 * torch.randn(model.alpha.shape, generator=g, dtype=torch.float64))
        model.lin_G.copy_(0.3 * torch.randn(model.lin_G.shape, generator=g, dtype=torch.float64))
        model.net.readout.weight.mul_(3.0)
    return model


def close(got, wanted, rel=1e-12) -> bool:
    scale = float(wanted.detach().abs().max())
    return got.shape == wanted.shape and torch.allclose(got, wanted, rtol=0, atol=rel * scale)


@pytest.mark.parametrize("layers", [1, 2])
@pytest.mark.parametrize("arch, activation", [("rnn", "tanh"), ("rnn", "relu"), ("lstm", "tanh"), ("gru", "tanh")])
def test_compiled_free_run_on_a_linear_path_and_its_gradients_equal_torch(arch, activation, layers, data, linear):
    torch.manual_seed(layers)
    model = corrected(path_model(arch, data, linear, layers=layers, activation=activation))
    g = torch.Generator().manual_seed(1)
    un = torch.randn(4, 70, data.n_u, generator=g, dtype=torch.float64)
    yn0 = torch.randn(4, data.n_y, generator=g, dtype=torch.float64, requires_grad=True)
    weight = torch.randn(4, 70, data.n_y, generator=g, dtype=torch.float64)
    rollout = cr.compiled_rollout(model)
    assert rollout is not None
    wanted, got = model.rollout_normalised(un, yn0), rollout(un, yn0)
    assert close(got, wanted)
    assert float((wanted - model.net.rollout_normalised(un, yn0)).detach().abs().max()) > 0.1  # the path is there
    inputs = [yn0, *model.parameters()]
    assert {n for n, _ in model.named_parameters()} >= {"alpha", "lin_G"}
    grads_wanted = torch.autograd.grad((wanted * weight).sum(), inputs)
    grads_got = torch.autograd.grad((got * weight).sum(), inputs)
    for (name, _), a, b in zip([("yn0", None), *model.named_parameters()], grads_got, grads_wanted):
        assert float(b.abs().max()) > 0, name
        assert close(a, b), name


def test_the_linear_path_without_a_gradient_and_in_float32(data, linear):
    model = corrected(path_model("gru", data, linear, layers=2))
    un = torch.randn(3, 40, data.n_u, dtype=torch.float64)
    yn0 = torch.randn(3, data.n_y, dtype=torch.float64)
    with torch.no_grad():  # inference: the C code keeps two steps and no raw outputs
        assert close(cr.compiled_rollout(model)(un, yn0), model.rollout_normalised(un, yn0))
    model = model.float()
    got = cr.compiled_rollout(model)(un.float(), yn0.float())
    assert close(got.double(), model.double().rollout_normalised(un, yn0), rel=1e-4)


def test_the_compiled_path_on_a_linear_path_applies_only_where_it_computes_the_same(data, linear):
    assert cr.compiled_rollout(path_model("lstm", data, linear)) is not None
    assert cr.compiled_rollout(path_model("mlp", data, linear)) is not None  # window_rollout.c
    assert cr.compiled_rollout(path_model("gru", data, linear, init_window=3)) is None
    dropout = path_model("gru", data, linear, dropout=0.2, layers=2)
    assert cr.compiled_rollout(dropout.train()) is None and cr.compiled_rollout(dropout.eval()) is not None
    noisy = path_model("gru", data, linear).train()
    noisy.feedback_noise = 0.1
    assert cr.compiled_rollout(noisy) is not None  # torch's draws, added in C


def test_feedback_noise_on_a_linear_path_is_torch_s_in_the_compiled_free_run(data, linear):
    model = corrected(path_model("gru", data, linear, layers=2)).train()
    model.feedback_noise = 0.3
    un = torch.randn(3, 40, data.n_u, dtype=torch.float64)
    yn0 = torch.randn(3, data.n_y, dtype=torch.float64, requires_grad=True)
    torch.manual_seed(5)
    wanted = model.rollout_normalised(un, yn0)
    torch.manual_seed(5)
    got = cr.compiled_rollout(model)(un, yn0)
    assert close(got, wanted)
    inputs = [yn0, *model.parameters()]
    for a, b in zip(torch.autograd.grad(got.sum(), inputs), torch.autograd.grad(wanted.sum(), inputs)):
        assert close(a, b)


@pytest.mark.parametrize("arch", ["gru", "tcn", "mlp"])
def test_a_training_on_a_linear_path_with_the_compiled_free_run_equals_one_in_torch(arch, data, linear, monkeypatch):
    config = ModelConfig(arch=arch, n_u=2, n_y=2, hidden=8, linear_order=linear.n_x)
    options = TrainConfig(epochs=2, batch_size=2, truncate=40, dtype="float64", patience=0)
    assert cr.compiled_rollout(build_model(config).double()) is not None
    fast = train(data, config, options, linear=linear)
    monkeypatch.setenv(cr.ENV_SWITCH, "0")
    plain = train(data, config, options, linear=linear)
    assert len(fast.history) == len(plain.history) == 3
    for a, b in zip(fast.history[1:], plain.history[1:]):
        assert a["train_loss"] == pytest.approx(b["train_loss"], rel=1e-9)
        assert a["valid_nrmse"] == pytest.approx(b["valid_nrmse"], rel=1e-9)
    assert fast.history[2]["train_loss"] != fast.history[1]["train_loss"]  # it trained
