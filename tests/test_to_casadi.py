"""torch -> CasADi: the exported (init, step) pair reproduces every network's free run in float64."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from torch import nn

from nnfmu.errors import ExportError
from nnfmu.export import casadi_model, to_casadi
from nnfmu.models import ModelConfig, build_model, load_model, save_checkpoint
from nnfmu.networks import RecurrentStepModel
from nnfmu.models.base import torch_threads
from nnfmu.training import TrainConfig, train
from builtin_networks import ARCHS

N_STEPS = 3500
NORM = {"u_mean": [100.0, 120.0], "u_std": [70.0, 60.0], "y_mean": [5e-4, 4e5], "y_std": [3e-4, 1.5e5]}


@pytest.fixture(scope="module")
def valve_inputs(valve_small):
    """3500 steps of measured valve inputs and the measured y0."""
    u = np.concatenate(valve_small.test.u)[:N_STEPS]
    return u, valve_small.test.y[0][0]


@pytest.fixture(scope="module")
def trained_models(valve_small):
    """Each architecture briefly trained (parallel) on a few valve trajectories: realistic weights."""
    data = valve_small.replace(splits={"train": valve_small.train.subset(range(8)),
                                       "valid": valve_small.train.subset([8]), "test": valve_small.test})
    cfg = TrainConfig(epochs=2, batch_size=8, truncate=30, lr=1e-2)
    with torch_threads(1):
        return {arch: train(data, ModelConfig(arch=arch, n_u=2, n_y=2, hidden=8, layers=2), cfg).model
                for arch in ARCHS}


def assert_same_free_run(model, u, y0):
    expected = model.simulate(u, y0)
    got = casadi_model(model).simulate(u, y0)
    scale = np.abs(expected).max(axis=0)  # relative to each output's magnitude
    assert np.isfinite(expected).all() and got.shape == expected.shape
    np.testing.assert_allclose(got / scale, expected / scale, rtol=0, atol=1e-9)


@pytest.mark.parametrize("arch", ARCHS)
def test_trained_networks_free_run_in_casadi_equals_torch(trained_models, valve_inputs, arch):
    assert_same_free_run(trained_models[arch], *valve_inputs)


def random_model(arch: str, seed: int = 0, **options):
    torch.manual_seed(seed)
    model = build_model(ModelConfig(arch=arch, n_u=2, n_y=2, hidden=12, **options))
    model.set_normalisation(NORM)
    return model


@pytest.mark.parametrize("arch, options", [
    ("tcn", dict(kernel_size=2, layers=4)),            # dilations 1, 2, 4, 8: window 16
    ("tcn", dict(layers=2, activation="relu", skip=False)),
    ("lstm", dict(layers=2)),
    ("gru", dict(layers=3, skip=False)),
    ("rnn", dict(layers=2, activation="relu", skip_scale=0.02)),
    ("mlp", dict(window=6, layers=3, activation="elu")),
    ("mlp", dict(activation="silu", skip=False)),
    ("mlp", dict(activation="sigmoid", layers=1, window=1)),
])
def test_architecture_variants_free_run_equal(valve_inputs, arch, options):
    assert_same_free_run(random_model(arch, **options), *valve_inputs)


@pytest.mark.parametrize("arch", ARCHS)
def test_one_step_from_a_random_state_matches_torch(arch):
    """A non-zero hidden state exercises every gate (the GRU's reset gate placement in particular)."""
    model = random_model(arch, layers=2).double().eval()
    init, step = to_casadi(model)
    rng = np.random.default_rng(1)
    x = rng.standard_normal(model.n_x)
    u = np.array([30.0, 200.0])
    with torch.no_grad():
        x_t, y_t = (a[0].numpy() for a in model.step(torch.from_numpy(x)[None], torch.from_numpy(u)[None]))
    x_c, y_c = (np.asarray(a).ravel() for a in step(x, u))
    np.testing.assert_allclose(x_c, x_t, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(y_c, y_t, rtol=1e-12)
    y0 = np.array([1e-4, 2e5])
    with torch.no_grad():
        x0_t = model.init(torch.from_numpy(y0)[None], torch.from_numpy(u)[None])[0].numpy()
    np.testing.assert_allclose(np.asarray(init(y0, u)).ravel(), x0_t, rtol=1e-13, atol=1e-15)


def test_gru_reset_gate_is_applied_after_the_hidden_product():
    """The exported GRU cell against the formula written out in numpy (PyTorch's nn.GRU semantics)."""
    model = random_model("gru", skip=False).double()
    model.set_normalisation({"u_mean": [0, 0], "u_std": [1, 1], "y_mean": [0, 0], "y_std": [1, 1]})
    _, step = to_casadi(model)
    layer, H = model.rnn_layers[0], 12
    W_ih, W_hh = layer.weight_ih_l0.detach().numpy(), layer.weight_hh_l0.detach().numpy()
    b_ih, b_hh = layer.bias_ih_l0.detach().numpy(), layer.bias_hh_l0.detach().numpy()
    rng = np.random.default_rng(2)
    y, h, u = rng.standard_normal(2), rng.standard_normal(H), rng.standard_normal(2)
    gi, gh = W_ih @ np.concatenate([y, u]) + b_ih, W_hh @ h + b_hh
    sig = lambda v: 1 / (1 + np.exp(-v))  # noqa: E731
    r, z = sig(gi[:H] + gh[:H]), sig(gi[H:2 * H] + gh[H:2 * H])
    n = np.tanh(gi[2 * H:] + r * gh[2 * H:])
    h_next = (1 - z) * n + z * h
    x_next, y_next = (np.asarray(a).ravel() for a in step(np.concatenate([y, h]), u))
    np.testing.assert_allclose(x_next[2:], h_next, rtol=1e-13)
    np.testing.assert_allclose(y_next, model.readout.weight.detach().numpy() @ h_next
                               + model.readout.bias.detach().numpy(), rtol=1e-12)


@pytest.mark.parametrize("arch", ARCHS)
def test_functions_have_named_ports_and_dense_mx_weights(arch):
    model = random_model(arch)
    init, step = to_casadi(model)
    assert init.name_in() == ["y0", "u0"] and init.name_out() == ["x0"]
    assert step.name_in() == ["x", "u"] and step.name_out() == ["x_next", "y_next"]
    assert step.size1_in(0) == model.n_x and step.is_a("MXFunction") and not step.has_free()
    weights = sum(p.numel() for p in model.parameters())
    assert step.n_nodes() < weights / 2  # weights stay dense matrices, not one graph node per weight


def test_casadi_model_carries_names_units_and_provenance(tmp_path):
    meta = {"name": "valve-test gru", "Ts": 4e-5,
            "inputs": [{"name": "u1", "unit": "V", "description": "supply pilot"}, {"name": "u2", "unit": "V"}],
            "outputs": [{"name": "s", "unit": "m"}, {"name": "p", "unit": "Pa"}]}
    model = build_model(ModelConfig(arch="gru", n_u=2, n_y=2, hidden=4), meta)
    path = save_checkpoint(tmp_path / "g.pt", model, train_config={"strategy": "parallel"}, best_epoch=7)
    cm = casadi_model(load_model(path))
    spec = cm.spec
    assert spec.name == "valve_test_gru" and spec.Ts == 4e-5
    assert [(v.name, v.unit) for v in spec.inputs] == [("u1", "V"), ("u2", "V")]
    assert spec.inputs[0].description == "supply pilot" and [v.unit for v in spec.outputs] == ["m", "Pa"]
    assert spec.source["checkpoint"] == str(path.resolve()) and spec.source["strategy"] == "parallel"
    assert spec.source["best_epoch"] == 7 and spec.source["arch"] == "gru"
    assert casadi_model(model, name="my_valve").spec.name == "my_valve"


def test_an_unsupported_layer_names_itself_and_the_supported_ones():
    model = random_model("mlp")
    model.net[1] = nn.Softsign()
    with pytest.raises(ExportError, match=r"layer 'net\.1' \(Softsign\) cannot be exported.*Linear, Conv1d, RNN"):
        to_casadi(model)

    class Wavelet(nn.Module):
        def forward(self, v):
            return torch.sin(v) * torch.exp(-v * v)

    tcn = random_model("tcn", layers=2)
    tcn.activation = Wavelet()
    with pytest.raises(ExportError, match=r"layer 'activation' \(Wavelet\).*supported layers are"):
        to_casadi(tcn)


def test_a_changed_computation_is_caught_by_the_verification():
    class DampedGRU(RecurrentStepModel):
        def apply_skip(self, yn, n):
            return 0.5 * yn + n  # not the documented skip connection

    torch.manual_seed(0)
    model = DampedGRU(ModelConfig(arch="gru", n_u=2, n_y=2, hidden=4))
    with pytest.raises(ExportError, match=r"exported x_next differs from the torch model.*DampedGRU"):
        to_casadi(model)


def test_something_that_is_not_a_step_model_is_refused():
    with pytest.raises(ExportError, match="cannot export a GRU; to_casadi exports the StepModels of nnfmu.models"):
        to_casadi(nn.GRU(2, 4))
