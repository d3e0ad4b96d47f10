"""Hybrid models: untrained == physics, torch == CasADi export, gradients, training, checkpoints, errors."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
import torch

from nnfmu.data import Trajectories
from nnfmu.errors import ConfigError, DataFileError, ShapeError, UnknownOptionError
from nnfmu.export import casadi_model, to_casadi
from nnfmu.hybrid import HybridConfig, HybridStepModel, load_physics_params
from nnfmu.models import build_model, load_model, save_checkpoint
from nnfmu.physics import ArmParams, ValveParams, arm_system, valve_system
from nnfmu.training import TrainConfig, train

WRONG_VALVE = {"k_s": 1.3 * 25e3, "C_max": 0.7 * 6e-10, "d_c": 0.0}  # spring, orifice 30 % off, no stop damping


pytestmark = pytest.mark.usefixtures("one_thread")


@pytest.fixture(scope="module")
def small(valve_small):
    """8 train, 2 valid, 1 test trajectory of the small valve dataset."""
    tr, te = valve_small.train, valve_small.test
    return valve_small.replace(splits={"train": tr.subset(range(8)), "valid": tr.subset([8, 9]),
                                       "test": Trajectories((te.u[0][:400],), (te.y[0][:400],))})


def _model(ds, **options) -> HybridStepModel:
    config = HybridConfig(n_u=2, n_y=2, **{"physics": "valve", "physics_params": WRONG_VALVE, **options})
    return build_model(config, ds.meta(), norm=ds.norm_stats("train"))


def _randomise(model: HybridStepModel, seed: int = 0) -> HybridStepModel:
    """Nonzero correction and moved physical parameters, so that every term of the step is exercised."""
    generator = torch.Generator().manual_seed(seed)
    with torch.no_grad():
        for prm in model.correction.parameters():
            prm.copy_(0.3 * torch.randn(prm.shape, generator=generator))
        model.physics_log_scale.copy_(0.02 * torch.randn(model.physics_log_scale.shape, generator=generator))
    return model


def _relative(got: np.ndarray, want: np.ndarray) -> float:
    return float(np.max(np.abs(got - want) / np.abs(want).max(axis=0)))


@pytest.mark.parametrize("correction", ["derivative", "step"])
def test_untrained_valve_hybrid_is_the_wrong_physics(small, correction):
    model = _model(small, correction=correction, train_physics=("k_s",))
    u, y = small.test.u[0][:300], small.test.y[0][:300]
    physics = valve_system(dataclasses.replace(ValveParams(), **WRONG_VALVE)).model()
    assert _relative(model.simulate(u, y[0]), physics.simulate(u, y[0])) < 1e-12


def test_untrained_arm_hybrid_is_the_physics():
    config = HybridConfig(n_u=6, n_y=6, physics="arm", physics_params={"m_payload": 100.0, "f_vis": [1500.0] * 6})
    model = build_model(config)
    rng = np.random.default_rng(0)
    u, y0 = rng.uniform(-5.0, 5.0, (6, 6)), np.array([10.0, -30.0, 40.0, 5.0, -20.0, 15.0])
    params = dataclasses.replace(ArmParams(), m_payload=100.0, f_vis=(1500.0,) * 6)
    assert _relative(model.simulate(u, y0)[1:], arm_system(params).model().simulate(u, y0)[1:]) < 1e-12


@pytest.mark.parametrize("correction,backend", [("derivative", "compiled"), ("step", "compiled"),
                                                ("derivative", "sx")])
def test_torch_step_equals_the_casadi_step(small, correction, backend):
    model = _randomise(_model(small, correction=correction, physics_backend=backend,
                              train_physics=("k_s", "C_max"))).double()
    init, step = to_casadi(model)
    p = model.physics_parameters().detach().numpy()
    scale = model._state_scale.numpy()
    u, y = small.test.u[0], small.test.y[0]
    with torch.no_grad():
        x_t = model.init(torch.tensor(y[:1]), torch.tensor(u[:1]))
        x_c = np.asarray(init(y[0], u[0], p)).ravel()
        for k in range(3):
            x_t, y_t = model.step(x_t, torch.tensor(u[k:k + 1]))
            x_c, y_c = (np.asarray(a).ravel() for a in step(x_c, u[k], p))
            assert np.max(np.abs(x_t[0].numpy() - x_c) / np.maximum(np.abs(x_c), scale)) < 1e-12
            assert np.max(np.abs(y_t[0].numpy() - y_c) / np.abs(y_c)) < 1e-12


def test_gradients_reach_the_physical_parameters_as_in_casadi(small):
    """d x_next / d theta by torch (through the compiled reverse mode) == CasADi's Jacobian d step / d p * dp/dtheta."""
    model = _randomise(_model(small, train_physics=("k_s", "C_max"))).double()
    _, step = to_casadi(model)
    u, y = small.test.u[0], small.test.y[0]
    x = model.init(torch.tensor(y[100:101]), torch.tensor(u[100:101])).detach()
    x_next, _ = model.step(x, torch.tensor(u[100:101]))
    p = model.physics_parameters().detach().numpy()
    jac = np.asarray(step.jacobian()(x[0].numpy(), u[100], p, 0, 0)[2])  # d x_next / d p
    names = [v.name for v in model.physics.parameters]
    trained = [names.index(n) for n in ("k_s", "C_max")]
    want = jac[:, trained] * p[trained] * model.config.train_physics_gain
    got = np.stack([torch.autograd.grad(x_next[0, i], model.physics_log_scale, retain_graph=True)[0].numpy()
                    for i in range(model.n_x)])
    assert np.all(np.abs(got - want) <= 1e-10 * np.abs(want).max(axis=0))
    assert np.abs(want).max() > 0


def test_training_reduces_the_validation_error_and_moves_the_parameters(small):
    config = HybridConfig(n_u=2, n_y=2, physics="valve", physics_params=WRONG_VALVE, hidden=8,
                          train_physics=("k_s", "C_max"))
    result = train(small, config, TrainConfig(epochs=2, truncate=60, batch_size=16, dtype="float64", patience=0))
    assert result.best_valid_nrmse < 0.8 * result.history[0]["valid_nrmse"]
    values = result.model.physics_parameter_values()
    assert values["k_s"] < WRONG_VALVE["k_s"] and values["C_max"] > WRONG_VALVE["C_max"]  # towards the truth


def test_checkpoint_round_trip_with_weights_only(small, tmp_path):
    model = _randomise(_model(small, train_physics=("k_s",), hidden=8))
    path = save_checkpoint(tmp_path / "h.pt", model)
    ckpt = torch.load(path, weights_only=True)
    assert ckpt["model_config"]["physics_params"] == dict(sorted(WRONG_VALVE.items()))
    loaded = load_model(path)
    assert isinstance(loaded, HybridStepModel) and loaded.config == model.config
    assert loaded.physics_parameter_values() == model.physics_parameter_values()
    u, y = small.test.u[0][:50], small.test.y[0][:50]
    np.testing.assert_array_equal(loaded.simulate(u, y[0]), model.simulate(u, y[0]))


def test_the_export_exposes_the_trained_physical_parameters(small):
    model = _randomise(_model(small, train_physics=("k_s",)))
    spec = casadi_model(model).spec
    start = {v.name: v.start for v in spec.parameters}
    assert start["k_s"] == model.physics_parameter_values()["k_s"] != WRONG_VALVE["k_s"]
    assert start["C_max"] == WRONG_VALVE["C_max"] and start["d_c"] == 0.0 and len(start) == 29


def test_series_parallel_training_is_refused(small):
    with pytest.raises(ConfigError, match="parallel mode only"):
        train(small, HybridConfig(n_u=2, n_y=2, physics="valve", hidden=4),
              TrainConfig(epochs=1, truncate=20, strategy="series-parallel", dtype="float64"))


@pytest.mark.parametrize("options,error,match", [
    ({"physics": "pendulum"}, ConfigError, "unknown physics.*'pendulum'.*arm, slider, valve"),
    ({"physics_params": {"k_spring": 1.0}}, UnknownOptionError, "unknown valve parameter.*'k_spring'.*k_s"),
    ({"physics_params": {"k_s": "stiff"}}, ConfigError, "'k_s' must be a finite number"),
    ({"physics_params": {"k_s": [1.0, 2.0]}}, ConfigError, "no tuple parameter 'k_s' of that length"),
    ({"train_physics": ("k_s", "spring")}, UnknownOptionError, "train_physics: unknown valve parameter.*'spring'"),
    ({"physics_params": {"d_c": 0.0}, "train_physics": ("d_c",)}, ConfigError, r"cannot train \['d_c'\].*value is 0"),
    ({"corrected_states": ("pressure",)}, UnknownOptionError, "unknown valve state.*'pressure'.*sdot"),
    ({"correction": "output"}, ConfigError, "unknown correction 'output'; choose one of derivative, step"),
    ({"physics": "arm"}, ShapeError, "the arm physics has n_u = 6, got 2"),
])
def test_bad_configurations_fail_clearly(options, error, match):
    with pytest.raises(error, match=match):
        HybridConfig(n_u=2, n_y=2, **{"physics": "valve", **options})


def test_data_in_other_units_is_refused(small):
    meta = small.meta()
    meta["outputs"][1]["unit"] = "bar"
    with pytest.raises(ConfigError, match="'bar' but the valve physics expects p in 'Pa'"):
        build_model(HybridConfig(n_u=2, n_y=2, physics="valve"), meta)


@pytest.mark.parametrize("content,error,match", [
    (None, DataFileError, "not found"),
    ("{k_s: 1}", ConfigError, "not valid JSON"),
    ("[1, 2]", ConfigError, "must hold a JSON object"),
])
def test_bad_parameter_files_fail_clearly(tmp_path, content, error, match):
    path = tmp_path / "params.json"
    if content is not None:
        path.write_text(content)
    with pytest.raises(error, match=match):
        load_physics_params(path)
