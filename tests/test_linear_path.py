"""A network on a linear path (ModelConfig.linear_order): it starts as the linear model, exactly, in torch,
CasADi and the FMU; training never ends worse than that start on validation."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from nnfmu.errors import ConfigError
from nnfmu.export import casadi_model
from nnfmu.linear import identify_linear
from nnfmu.models import ModelConfig, build_model, load_model
from nnfmu.training import TrainConfig, dataset_meta, train
from nnfmu.training.linear_start import start_linear_path
from tests.test_linear import dataset, true_system

pytestmark = pytest.mark.usefixtures("one_thread")
from builtin_networks import ARCHS


@pytest.fixture(scope="module")
def data():
    return dataset(true_system(), noise=0.01)


@pytest.fixture(scope="module")
def linear(data):
    return identify_linear(data)


def path_model(arch, data, linear, **options):
    config = ModelConfig(arch=arch, n_u=data.n_u, n_y=data.n_y, hidden=8, linear_order=linear.n_x, **options)
    model = build_model(config, dataset_meta(data, arch), norm=data.norm_stats("train")).double()
    start_linear_path(model, data, linear)
    return model


def rel(a, b) -> float:
    return float(np.max(np.abs(np.asarray(a) - np.asarray(b))) / np.max(np.abs(b)))


@pytest.mark.parametrize("arch", ARCHS)
def test_with_its_correction_at_zero_the_network_is_the_linear_model(arch, data, linear):
    model = path_model(arch, data, linear)
    for u, y in zip(data.test.u, data.test.y):
        assert rel(model.simulate(u, y[0]), linear.simulate(u, y[0])) < 1e-9


@pytest.mark.parametrize("arch", ARCHS)
def test_casadi_export_reproduces_the_trained_path(arch, data, linear):
    model = path_model(arch, data, linear, init_window=3 if arch in ("gru", "mlp") else 1)
    with torch.no_grad():  # a correction that is not zero, and a moved linear part
        model.alpha.copy_(torch.tensor([0.3, -0.2], dtype=torch.float64))
        model.lin_G.copy_(0.1 * torch.ones_like(model.lin_G))
    u, y = data.test.u[0], data.test.y[0]
    assert rel(casadi_model(model).simulate(u, y[0]), model.simulate(u, y[0])) < 1e-9


def test_checkpoint_round_trip_keeps_the_linear_path(data, linear, tmp_path):
    result = train(data, ModelConfig(arch="gru", n_u=2, n_y=2, hidden=8, linear_order=linear.n_x),
                   TrainConfig(epochs=3, batch_size=2, dtype="float64"), out=tmp_path / "m.pt", linear=linear)
    loaded = load_model(tmp_path / "m.pt")
    u, y = data.test.u[0], data.test.y[0]
    assert rel(loaded.simulate(u, y[0]), result.model.simulate(u, y[0])) < 1e-12


@pytest.mark.parametrize("arch", ("gru", "mlp"))
def test_training_starts_at_the_linear_model_and_never_ends_worse(arch, data, linear):
    result = train(data, ModelConfig(arch=arch, n_u=2, n_y=2, hidden=8, linear_order=linear.n_x),
                   TrainConfig(epochs=4, batch_size=2), linear=linear)
    start = result.history[0]["valid_nrmse"]
    assert start == pytest.approx(linear.info["nrmse_valid"], rel=1e-3)  # epoch 0 is the linear model (float32)
    assert result.best_valid_nrmse <= start


def test_linear_path_refuses_increment_mode_and_another_order(data, linear):
    with pytest.raises(ConfigError, match="increment"):
        ModelConfig(arch="gru", n_u=2, n_y=2, linear_order=2, increment=True)
    model = build_model(ModelConfig(arch="gru", n_u=2, n_y=2, linear_order=linear.n_x + 1))
    with pytest.raises(ConfigError, match="linear_order"):
        start_linear_path(model, data, linear)


def test_the_fmu_of_an_untrained_path_simulates_the_linear_model(data, linear, tmp_path):
    """Issue 21's check: the correction at zero reproduces the linear model's free run, and so does its FMU (fmpy)."""
    from nnfmu.cosim import FmuSimulator
    from nnfmu.export import build_fmu

    model = path_model("gru", data, linear)
    fmu = build_fmu(casadi_model(model, name="gru_on_linear"), tmp_path / "m.fmu")
    u, y = data.test.u[0], data.test.y[0]
    with FmuSimulator(fmu, data.input_names, data.output_names, data.Ts) as sim:
        got = sim.simulate(u, y[0])
    assert rel(got, linear.simulate(u, y[0])) < 1e-9
