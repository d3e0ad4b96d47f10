"""The compiled free run of the window networks (nnfmu/training/window_rollout.c: the TCN and the MLP) computes what
torch's loop over their step computes: outputs and the gradients of every weight and of ``yn0``, in float64, for
every activation, depths, kernels and windows, widths around the C vector blocks, with and without a linear path.
A training with it equals one in torch: tests/test_compiled_linear_path.py."""

from __future__ import annotations

import pytest
import torch

from nnfmu.models import ModelConfig, build_model
from nnfmu.training import compiled_rollout as cr
from tests.test_linear_path import data, linear, path_model  # noqa: F401 (module fixtures)

pytestmark = pytest.mark.usefixtures("one_thread")

CASES = [  # arch, activation, layers, kernel (TCN) or window (MLP), hidden, skip
    ("tcn", "tanh", 3, 3, 8, True), ("tcn", "tanh", 1, 5, 21, False), ("tcn", "relu", 2, 2, 16, True),
    ("tcn", "sigmoid", 3, 2, 7, True), ("tcn", "elu", 2, 3, 33, False), ("tcn", "silu", 4, 2, 9, True),
    ("mlp", "tanh", 2, 10, 16, True), ("mlp", "relu", 1, 3, 21, False), ("mlp", "silu", 3, 1, 8, True),
    ("mlp", "elu", 2, 4, 33, True), ("mlp", "sigmoid", 2, 6, 7, False),
]


def close(got, wanted, rel=1e-12) -> bool:
    scale = float(wanted.detach().abs().max())
    return got.shape == wanted.shape and float((got - wanted).detach().abs().max()) <= rel * scale


def network(arch, activation, layers, taps, hidden, skip):
    torch.manual_seed(layers * 10 + taps)
    sizes = {"kernel_size": taps} if arch == "tcn" else {"window": taps}
    config = ModelConfig(arch=arch, n_u=3, n_y=2, hidden=hidden, layers=layers, activation=activation, skip=skip,
                         **sizes)
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


@pytest.mark.parametrize("arch, activation, layers, taps, hidden, skip", CASES)
def test_compiled_free_run_and_its_gradients_equal_torch_in_float64(arch, activation, layers, taps, hidden, skip):
    agree(network(arch, activation, layers, taps, hidden, skip), n_u=3, n_y=2)


@pytest.mark.parametrize("arch, activation", [("tcn", "tanh"), ("tcn", "silu"), ("mlp", "tanh")])
def test_on_a_linear_path_too(arch, activation, data, linear):
    model = path_model(arch, data, linear, activation=activation)
    g = torch.Generator().manual_seed(3)
    with torch.no_grad():  # a correction that is not zero: G, alpha and the output layer all reach the output
        model.alpha.copy_(0.5 * torch.randn(model.alpha.shape, generator=g, dtype=torch.float64))
        model.lin_G.copy_(0.3 * torch.randn(model.lin_G.shape, generator=g, dtype=torch.float64))
        (model.net.head if arch == "tcn" else model.net.net[-1]).weight.mul_(3.0)
    agree(model, data.n_u, data.n_y)


@pytest.mark.parametrize("arch", ["tcn", "mlp"])
def test_inference_keeps_a_ring_of_the_receptive_field_and_float32_agrees(arch):
    model = network(arch, "tanh", 3, 3, 16, True).eval()
    g = torch.Generator().manual_seed(2)
    un = torch.randn(2, 300, 3, generator=g, dtype=torch.float64)  # 300 steps: the ring (TCN: 9) wraps many times
    yn0 = torch.randn(2, 2, generator=g, dtype=torch.float64)
    with torch.no_grad():
        wanted = model.rollout_normalised(un, yn0)
        assert close(cr.compiled_rollout(model)(un, yn0), wanted)
        single = model.float()
        got = cr.compiled_rollout(single)(un.float(), yn0.float())
    assert close(got.double(), wanted, rel=1e-4)


@pytest.mark.parametrize("arch", ["tcn", "mlp"])
def test_the_compiled_path_applies_only_where_it_computes_the_same(arch, data, linear):
    base = dict(arch=arch, n_u=2, n_y=1, hidden=8, layers=2)
    assert cr.compiled_rollout(build_model(ModelConfig(**base))) is not None
    assert cr.compiled_rollout(build_model(ModelConfig(**base, increment=True))) is None  # relative taps: torch's
    assert cr.compiled_rollout(build_model(ModelConfig(**base, init_window=4))) is None
    dropout = build_model(ModelConfig(**base, dropout=0.2))
    assert cr.compiled_rollout(dropout.train()) is None and cr.compiled_rollout(dropout.eval()) is not None
    noisy = path_model(arch, data, linear).train()
    noisy.feedback_noise = 0.1  # unlike the recurrent cells' C code, this one adds the noise (test below)
    assert cr.compiled_rollout(noisy) is not None


@pytest.mark.parametrize("arch, on_path", [("tcn", False), ("tcn", True), ("mlp", False), ("mlp", True)])
def test_with_feedback_noise_the_compiled_free_run_draws_and_adds_what_torch_does(arch, on_path, data, linear):
    """In training with feedback noise the fed-back output is disturbed and the rest state is not: the C code
    gets torch's own draws, so values and gradients equal torch's loop for the same seed."""
    if on_path:
        model = path_model(arch, data, linear).train()
        with torch.no_grad():
            model.alpha.fill_(0.4)
            model.lin_G.fill_(0.2)
    else:
        model = network(arch, "tanh", 2, 3, 8, True).train()
    model.feedback_noise = 0.3
    n_u, n_y = model.config.n_u, model.config.n_y
    g = torch.Generator().manual_seed(4)
    un = torch.randn(3, 40, n_u, generator=g, dtype=torch.float64)
    yn0 = torch.randn(3, n_y, generator=g, dtype=torch.float64, requires_grad=True)
    weight = torch.randn(3, 40, n_y, generator=g, dtype=torch.float64)
    torch.manual_seed(7)
    wanted = model.rollout_normalised(un, yn0)
    torch.manual_seed(7)
    got = cr.compiled_rollout(model)(un, yn0)
    torch.manual_seed(8)
    other = cr.compiled_rollout(model)(un, yn0)
    assert close(got, wanted) and not close(other, wanted, rel=1e-3)  # the noise is there, and it is torch's
    inputs = [yn0, *model.parameters()]
    for a, b in zip(torch.autograd.grad((got * weight).sum(), inputs), torch.autograd.grad((wanted * weight).sum(),
                                                                                             inputs)):
        assert close(a, b)
