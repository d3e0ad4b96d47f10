"""The compiled free run of the TCN (nnfmu/training/tcn_rollout.c) computes what torch's loop over the TCN's step
computes: outputs and the gradients of every weight and of ``yn0``, in float64, for every activation, depths and
kernels, widths around the C vector blocks, with and without a linear path; and a training with it equals one in
torch."""

from __future__ import annotations

import pytest
import torch

from nnfmu.models import ModelConfig, build_model
from nnfmu.training import TrainConfig, train
from nnfmu.training import compiled_rollout as cr
from tests.test_linear_path import data, linear, path_model  # noqa: F401 (module fixtures)

pytestmark = pytest.mark.usefixtures("one_thread")

CASES = [  # activation, layers, kernel, hidden, skip
    ("tanh", 3, 3, 8, True), ("tanh", 1, 5, 21, False), ("relu", 2, 2, 16, True), ("sigmoid", 3, 2, 7, True),
    ("elu", 2, 3, 33, False), ("silu", 4, 2, 9, True),
]


def close(got, wanted, rel=1e-12) -> bool:
    scale = float(wanted.detach().abs().max())
    return got.shape == wanted.shape and float((got - wanted).detach().abs().max()) <= rel * scale


def tcn(activation, layers, kernel, hidden, skip):
    torch.manual_seed(layers * 10 + kernel)
    config = ModelConfig(arch="tcn", n_u=3, n_y=2, hidden=hidden, layers=layers, kernel_size=kernel,
                         activation=activation, skip=skip)
    model = build_model(config).double()
    with torch.no_grad():  # weights large enough that every layer's activation is far from linear
        for p in model.parameters():
            p.mul_(2.0)
    return model


def agree(model, n_u, n_y, batch=4, steps=50):
    """Assert that the compiled free run and its gradients (of yn0 and every parameter) equal torch's."""
    g = torch.Generator().manual_seed(1)
    un = torch.randn(batch, steps, n_u, generator=g, dtype=torch.float64)
    yn0 = torch.randn(batch, n_y, generator=g, dtype=torch.float64, requires_grad=True)
    weight = torch.randn(batch, steps, n_y, generator=g, dtype=torch.float64)
    rollout = cr.compiled_rollout(model)
    assert rollout is not None
    wanted, got = model.rollout_normalised(un, yn0), rollout(un, yn0)
    assert close(got, wanted)
    names = ["yn0", *(n for n, _ in model.named_parameters())]
    inputs = [yn0, *model.parameters()]
    grads_wanted = torch.autograd.grad((wanted * weight).sum(), inputs)
    grads_got = torch.autograd.grad((got * weight).sum(), inputs)
    for name, a, b in zip(names, grads_got, grads_wanted):
        assert float(b.abs().max()) > 0, name
        assert close(a, b), name


@pytest.mark.parametrize("activation, layers, kernel, hidden, skip", CASES)
def test_compiled_tcn_free_run_and_its_gradients_equal_torch_in_float64(activation, layers, kernel, hidden, skip):
    agree(tcn(activation, layers, kernel, hidden, skip), n_u=3, n_y=2)


@pytest.mark.parametrize("activation", ["tanh", "silu"])
def test_on_a_linear_path_too(activation, data, linear):
    model = path_model("tcn", data, linear, activation=activation)
    g = torch.Generator().manual_seed(3)
    with torch.no_grad():  # a correction that is not zero: G, alpha and the head all reach the output
        model.alpha.copy_(0.5 * torch.randn(model.alpha.shape, generator=g, dtype=torch.float64))
        model.lin_G.copy_(0.3 * torch.randn(model.lin_G.shape, generator=g, dtype=torch.float64))
        model.net.head.weight.mul_(3.0)
    agree(model, data.n_u, data.n_y)


def test_inference_keeps_a_ring_of_the_receptive_field_and_float32_agrees():
    model = tcn("tanh", 3, 3, 16, True).eval()
    g = torch.Generator().manual_seed(2)
    un = torch.randn(2, 300, 3, generator=g, dtype=torch.float64)  # 300 steps: the ring of 15 wraps many times
    yn0 = torch.randn(2, 2, generator=g, dtype=torch.float64)
    with torch.no_grad():
        wanted = model.rollout_normalised(un, yn0)
        assert close(cr.compiled_rollout(model)(un, yn0), wanted)
        single = model.float()
        got = cr.compiled_rollout(single)(un.float(), yn0.float())
    assert close(got.double(), wanted, rel=1e-4)


def test_the_compiled_tcn_applies_only_where_it_computes_the_same(data, linear):
    base = dict(arch="tcn", n_u=2, n_y=1, hidden=8, layers=2)
    assert cr.compiled_rollout(build_model(ModelConfig(**base))) is not None
    assert cr.compiled_rollout(build_model(ModelConfig(**base, increment=True))) is None  # relative taps: torch's
    assert cr.compiled_rollout(build_model(ModelConfig(**base, init_window=4))) is None
    dropout = build_model(ModelConfig(**base, dropout=0.2))
    assert cr.compiled_rollout(dropout.train()) is None and cr.compiled_rollout(dropout.eval()) is not None
    noisy = path_model("tcn", data, linear).train()
    noisy.feedback_noise = 0.1
    assert cr.compiled_rollout(noisy) is None and cr.compiled_rollout(noisy.eval()) is not None


def test_a_tcn_training_with_the_compiled_free_run_equals_one_in_torch(data, linear, monkeypatch):
    config = ModelConfig(arch="tcn", n_u=data.n_u, n_y=data.n_y, hidden=8, layers=2, linear_order=linear.n_x)
    options = TrainConfig(epochs=2, batch_size=2, truncate=40, dtype="float64", patience=0)
    fast = train(data, config, options, linear=linear)
    monkeypatch.setenv(cr.ENV_SWITCH, "0")
    plain = train(data, config, options, linear=linear)
    assert len(fast.history) == len(plain.history) == 3
    for a, b in zip(fast.history[1:], plain.history[1:]):
        assert a["train_loss"] == pytest.approx(b["train_loss"], rel=1e-9)
        assert a["valid_nrmse"] == pytest.approx(b["valid_nrmse"], rel=1e-9)
    assert fast.history[-1]["train_loss"] != fast.history[1]["train_loss"]  # it trained
