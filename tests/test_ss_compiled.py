"""The ss network's compiled state loop (nnfmu/ss/state_loop.c) computes what torch's loop computes: the free run and
the gradients of every weight, of the initial output and of the init window, in float64, for every activation,
depths and widths around the C vector blocks; and a training with it is the training in torch."""

from __future__ import annotations

import pytest
import torch

from nnfmu.models import ModelConfig, build_model, load_model
from nnfmu.ss import compiled
from nnfmu.ss.compiled import compiled_states
from nnfmu.training import TrainConfig, train
from tests.test_linear_path import data, linear  # noqa: F401 (the fixtures)

pytestmark = pytest.mark.usefixtures("one_thread")

CASES = [("tanh", 2, 16), ("tanh", 1, 7), ("relu", 3, 33), ("sigmoid", 2, 9), ("elu", 1, 64), ("silu", 2, 21)]


def network(activation, layers, hidden):
    torch.manual_seed(layers * 100 + hidden)
    config = ModelConfig.from_dict({"arch": "ss", "n_u": 3, "n_y": 2, "hidden": hidden, "layers": layers,
                                    "activation": activation, "states": 5, "init_window": 4})
    model = build_model(config).double()
    with torch.no_grad():  # a stable linear part and a map f far from linear
        model.lin_A.copy_(0.6 * torch.eye(5) + 0.1 * torch.randn(5, 5, dtype=torch.float64))
        for name in ("lin_B", "lin_C", "lin_Ky", "lin_Ku"):
            getattr(model, name).normal_()
        for p in model.parameters():  # none at zero (the encoder's last layer starts there)
            p.mul_(2.0).add_(0.1 * torch.randn_like(p))
    return model


def free_run_and_gradients(model, compiled: bool, monkeypatch):
    monkeypatch.setenv("NNFMU_COMPILED_ROLLOUT", "1" if compiled else "0")
    assert (compiled_states(model) is not None) == compiled
    g = torch.Generator().manual_seed(1)
    un = torch.randn(4, 60, 3, generator=g, dtype=torch.float64)
    yn_win = torch.randn(4, 4, 2, generator=g, dtype=torch.float64, requires_grad=True)
    weight = torch.randn(4, 57, 2, generator=g, dtype=torch.float64)
    x0 = model.init_window_norm(yn_win, un[:, :4])
    ys = model.free_run_norm(un[:, 3:], yn_win[:, -1], x0)
    inputs = [yn_win, *model.parameters()]
    return ys.detach(), torch.autograd.grad((ys * weight).sum(), inputs)


@pytest.mark.parametrize("activation, layers, hidden", CASES)
def test_the_compiled_state_loop_gives_torchs_free_run_and_gradients(activation, layers, hidden, monkeypatch):
    model = network(activation, layers, hidden)
    names = ["the init window", *(n for n, _ in model.named_parameters())]
    ys, grads = free_run_and_gradients(model, True, monkeypatch)
    ys_torch, grads_torch = free_run_and_gradients(model, False, monkeypatch)
    assert float((ys - ys_torch).abs().max()) <= 1e-12 * float(ys_torch.abs().max())
    for name, got, wanted in zip(names, grads, grads_torch):
        assert float(wanted.abs().max()) > 0, name  # every weight (and the window) reaches the loss
        assert float((got - wanted).abs().max()) <= 1e-11 * float(wanted.abs().max()), name


def test_a_training_with_the_compiled_loop_is_the_training_in_torch(data, linear, tmp_path, monkeypatch):
    """Same seed, float64: the kept weights and the validation history agree to rounding with and without C."""
    config = ModelConfig.from_dict({"arch": "ss", "n_u": 2, "n_y": 2, "hidden": 8, "init_window": 5,
                                    "linear_order": linear.n_x})
    runs, calls = {}, []
    loop = compiled._apply
    monkeypatch.setattr(compiled, "_apply", lambda *args: calls.append(1) or loop(*args))
    for switch in ("1", "0"):
        monkeypatch.setenv("NNFMU_COMPILED_ROLLOUT", switch)
        calls.clear()
        result = train(data, config, TrainConfig(epochs=4, batch_size=2, truncate=40, dtype="float64", patience=0),
                       out=tmp_path / f"ss{switch}.pt", linear=linear)
        runs[switch] = (result, load_model(tmp_path / f"ss{switch}.pt").double())
        assert bool(calls) == (switch == "1")  # C ran the loop in the first training, torch in the second
    (fast, fast_model), (slow, slow_model) = runs["1"], runs["0"]
    assert [h["valid_nrmse"] for h in fast.history] == pytest.approx([h["valid_nrmse"] for h in slow.history],
                                                                     rel=1e-9)
    assert fast.history[-1]["valid_nrmse"] != fast.history[0]["valid_nrmse"]  # it trained
    for (name, a), b in zip(fast_model.named_parameters(), slow_model.parameters()):
        assert torch.allclose(a, b, rtol=1e-9, atol=1e-12), name
