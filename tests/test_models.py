"""The step interface of the five networks: exact free run, fused teacher forcing, shapes, normalisation."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from nnfmu.errors import ConfigError, DataError, ShapeError, UnknownOptionError
from nnfmu.models import ModelConfig, StepModel, build_model
from builtin_networks import ARCHS

N_U, N_Y = 2, 3


def make_model(arch: str, *, seed: int = 0, dtype=torch.float64, **options) -> StepModel:
    """A float64 model with non-trivial weights and normalisation, in eval mode."""
    torch.manual_seed(seed)
    options = {"hidden": 6, "layers": 2, "skip_scale": 0.5, **options}
    model = build_model(ModelConfig(arch=arch, n_u=N_U, n_y=N_Y, **options))
    model.set_normalisation({"u_mean": [1.0, -2.0], "u_std": [0.5, 3.0],
                             "y_mean": [0.1, 10.0, -1.0], "y_std": [2.0, 0.25, 1.5]})
    return model.to(dtype).eval()


def random_io(batch: int, steps: int, seed: int = 1, dtype=torch.float64):
    g = torch.Generator().manual_seed(seed)
    u = torch.randn(batch, steps, N_U, generator=g, dtype=dtype)
    y = torch.randn(batch, steps, N_Y, generator=g, dtype=dtype)
    return u, y


def step_loop(model: StepModel, u: torch.Tensor, y0: torch.Tensor) -> torch.Tensor:
    """The caller's loop over the public step, as the docstring shows it."""
    x = model.init(y0, u[:, 0])
    ys = [y0]
    for k in range(u.shape[1] - 1):
        x, y = model.step(x, u[:, k])
        ys.append(y)
    return torch.stack(ys, dim=1)


VARIANTS = [(arch, {}) for arch in ARCHS] + [
    ("mlp", dict(window=1)), ("tcn", dict(kernel_size=2, layers=3)), ("gru", dict(layers=1, skip=False)),
    ("rnn", dict(activation="relu", layers=3)), ("lstm", dict(layers=1)),
]


@pytest.mark.parametrize("arch, options", VARIANTS)
@pytest.mark.parametrize("batch", [1, 3])
def test_free_run_equals_python_loop_over_step_exactly(arch, options, batch):
    model = make_model(arch, **options)
    u, y = random_io(batch, 40)
    with torch.no_grad():
        assert torch.equal(model(u, y[:, 0]), step_loop(model, u, y[:, 0]))


@pytest.mark.parametrize("arch", ARCHS)
@pytest.mark.parametrize("skip", [True, False])
def test_fused_teacher_forcing_equals_the_step_loop_fed_with_measurements(arch, skip):
    model = make_model(arch, skip=skip)
    u, y = random_io(2, 30)
    with torch.no_grad():
        fused = model(u, y[:, 0], y)
        un, yn = model.normalise_u(u), model.normalise_y(y)
        generic = StepModel.teacher_forced_norm(model, un, yn)  # loop over step_norm with y injected
    assert fused.shape == y.shape
    torch.testing.assert_close(fused[:, 1:], model.denormalise_y(generic), rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize("arch", ["mlp", "tcn"])
def test_window_teacher_forcing_sees_measured_history(arch):
    """For window models, a teacher-forced prediction equals a free step from the measured window."""
    model = make_model(arch)
    u, y = random_io(2, 3 * model.config.window)
    with torch.no_grad():
        fused = model(u, y[:, 0], y)
        k = 2 * model.config.window  # a step whose window lies entirely inside the record
        L = model.config.window
        x = model.state_from_window(model.normalise_y(y[:, k - L + 1:k + 1]), model.normalise_u(u[:, k - L + 1:k]))
        _, y_next = model.step(x, u[:, k])
    torch.testing.assert_close(fused[:, k + 1], y_next, rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize("arch", ARCHS)
def test_teacher_forced_and_free_run_coincide_at_first_step(arch):
    model = make_model(arch)
    u, y = random_io(3, 20)
    y[:, 0] = torch.tensor([0.3, 9.0, -2.0])
    with torch.no_grad():
        free, forced = model(u, y[:, 0]), model(u, y[:, 0], y)
    torch.testing.assert_close(free[:, :2], forced[:, :2], rtol=1e-12, atol=1e-12)
    assert not torch.allclose(free[:, 2:], forced[:, 2:])  # afterwards the fed outputs differ


@pytest.mark.parametrize("arch", ARCHS)
def test_simulate_is_float64_numpy_free_run_starting_at_y0(arch):
    model = make_model(arch, dtype=torch.float32)
    u, y = random_io(1, 25)
    out = model.simulate(u[0].numpy(), y[0, 0].numpy())
    assert out.dtype == np.float64 and out.shape == (25, N_Y)
    np.testing.assert_array_equal(out[0], y[0, 0].numpy())
    with torch.no_grad():
        ref = model.double()(u, y[:, 0])[0].numpy()
    np.testing.assert_allclose(out, ref, rtol=1e-13, atol=1e-13)
    assert model.simulate(u[0, :1].numpy(), y[0, 0].numpy()).shape == (1, N_Y)


def test_simulate_rejects_wrong_shapes_and_nan():
    model = make_model("gru")
    with pytest.raises(ShapeError, match=r"u has shape \(10,\), expected \(n_steps, 2\)"):
        model.simulate(np.zeros(10), np.zeros(N_Y))
    with pytest.raises(ShapeError, match=r"y0 has shape \(2,\), expected \(3,\)"):
        model.simulate(np.zeros((10, N_U)), np.zeros(2))
    with pytest.raises(DataError, match="non-finite"):
        model.simulate(np.full((10, N_U), np.nan), np.zeros(N_Y))


def test_step_and_forward_reject_wrong_shapes():
    model = make_model("lstm")
    x0 = model.init(torch.zeros(2, N_Y, dtype=torch.float64), torch.zeros(2, N_U, dtype=torch.float64))
    with pytest.raises(ShapeError, match=r"u has shape \(2, 3\), expected a tensor of shape \(2, 2\)"):
        model.step(x0, torch.zeros(2, 3))
    with pytest.raises(ShapeError, match=r"x has shape"):
        model.step(x0[:, 1:], torch.zeros(2, N_U))
    with pytest.raises(ShapeError, match=r"y_meas has shape"):
        model(torch.zeros(2, 5, N_U), torch.zeros(2, N_Y), torch.zeros(2, 4, N_Y))


@pytest.mark.parametrize("arch, n_x", [("mlp", 4 * 3 + 3 * 2), ("tcn", 3 + 2 * 5 + 4 * 6 + 8 * 6), ("rnn", 3 + 2 * 6),
                                       ("gru", 3 + 2 * 6), ("lstm", 3 + 2 * 2 * 6)])
def test_state_layout_is_the_documented_flat_vector(arch, n_x):
    """to_casadi and the FMU rely on this layout (see the module docstrings)."""
    model = make_model(arch, layers=None if arch in ("mlp", "tcn") else 2)
    assert model.n_x == n_x
    y0 = torch.tensor([[1.0, 10.5, 0.5]], dtype=torch.float64)
    u0 = torch.tensor([[2.0, 1.0]], dtype=torch.float64)
    yn0, un0 = model.normalise_y(y0), model.normalise_u(u0)
    x0 = model.init(y0, u0)
    if arch == "mlp":
        L = model.config.window
        torch.testing.assert_close(x0, torch.cat([yn0.repeat(1, L), un0.repeat(1, L - 1)], dim=1))
    elif arch == "tcn":  # y_k, then the first layer's delay line: k - 1 = 2 samples [y0, u0] at rest
        torch.testing.assert_close(x0[:, :N_Y + 2 * 5], torch.cat([yn0, yn0, un0, yn0, un0], dim=1))
    else:
        torch.testing.assert_close(x0, torch.cat([yn0, torch.zeros(1, n_x - N_Y, dtype=torch.float64)], dim=1))
    x1, y1 = model.step(x0, u0)
    L = model.config.window
    newest = slice(L * N_Y - N_Y, L * N_Y) if arch == "mlp" else slice(0, N_Y)
    torch.testing.assert_close(x1[:, newest], model.normalise_y(y1), rtol=1e-12, atol=1e-12)


def test_normalisation_lives_in_buffers_and_model_works_in_physical_units():
    model = make_model("gru")
    state = model.state_dict()
    assert {"u_mean", "u_std", "y_mean", "y_std"} <= set(state)
    twin = make_model("gru")
    twin.set_normalisation({"u_mean": [0, 0], "u_std": [1, 1], "y_mean": [0, 0, 0], "y_std": [1, 1, 1]})
    u, y = random_io(2, 15)
    with torch.no_grad():
        physical = model(u, y[:, 0])
        # the same network fed pre-normalised data, with identity normalisation, gives normalised outputs
        normalised = twin(model.normalise_u(u), model.normalise_y(y[:, 0]))
    torch.testing.assert_close(model.normalise_y(physical[:, 1:]), normalised[:, 1:], rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize("arch", ARCHS)
def test_dropout_acts_in_training_only(arch):
    model = make_model(arch, dropout=0.5)
    u, y = random_io(2, 12)
    with torch.no_grad():
        assert torch.equal(model(u, y[:, 0]), model(u, y[:, 0]))
        model.train()
        assert not torch.equal(model(u, y[:, 0]), model(u, y[:, 0]))


@pytest.mark.parametrize("config, match", [
    (dict(arch="gru", window=5), "window must be 1"),
    (dict(arch="tcn", layers=2, kernel_size=3, window=9), "sees 7 samples, got window=9"),
    (dict(arch="mlp", hidden=0), "hidden must be a positive integer"),
    (dict(arch="lstm", layers=0), "layers must be a positive integer"),
    (dict(arch="tcn", kernel_size=1), "kernel_size >= 2"),
])
def test_inconsistent_sizes_fail_at_construction(config, match):
    with pytest.raises(ShapeError, match=match):
        ModelConfig(n_u=N_U, n_y=N_Y, **config)


def test_meta_inconsistent_with_config_is_a_shape_error():
    config = ModelConfig(arch="gru", n_u=N_U, n_y=N_Y)
    meta = {"Ts": 0.1, "inputs": [{"name": "a", "unit": "V"}], "outputs": [{"name": "y", "unit": ""}] * 3}
    with pytest.raises(ShapeError, match=r"meta\['inputs'\] must list 2 channels"):
        build_model(config, meta)


def test_sub_network_mismatch_is_caught_by_the_dry_run():
    class BrokenGRU(type(make_model("gru"))):
        def __init__(self, config):
            super().__init__(config)
            self.readout = torch.nn.Linear(config.hidden + 1, config.n_y)  # does not fit the cell
            self.check_sizes()

    with pytest.raises(ShapeError, match="inconsistent layer sizes"):
        BrokenGRU(ModelConfig(arch="gru", n_u=N_U, n_y=N_Y))


def test_config_options_are_checked():
    with pytest.raises(ConfigError, match="unknown architecture 'cnn'; choose one of gru, hybrid, lstm, mlp, node, rnn, ss, tcn"):
        ModelConfig(arch="cnn", n_u=1, n_y=1)
    with pytest.raises(UnknownOptionError, match="unknown RecurrentConfig option.*'hiden'.*valid options are"):
        ModelConfig.from_dict({"arch": "gru", "n_u": 1, "n_y": 1, "hiden": 8})
    with pytest.raises(ConfigError, match="activation 'elu' is not available for arch 'rnn'"):
        ModelConfig(arch="rnn", n_u=1, n_y=1, activation="elu")
    config = ModelConfig(arch="tcn", n_u=1, n_y=1, layers=2)
    assert config.window == 7 and config.replace(layers=3).window == 15
    assert ModelConfig.from_dict(config.to_dict()) == config


@pytest.mark.parametrize("arch", ARCHS)
def test_parallel_rollout_passes_gradcheck(arch):
    """Gradients of the free run w.r.t. inputs, initial output and weights, in float64."""
    torch.manual_seed(3)
    model = build_model(ModelConfig(arch=arch, n_u=1, n_y=2, hidden=3, layers=2, skip_scale=0.5,
                                    kernel_size=2)).double()
    names = [n for n, _ in model.named_parameters()][:2] + [n for n, _ in model.named_parameters()][-1:]
    params = dict(model.named_parameters())
    g = torch.Generator().manual_seed(4)
    u = torch.randn(2, 6, 1, generator=g, dtype=torch.float64, requires_grad=True)
    y0 = torch.randn(2, 2, generator=g, dtype=torch.float64, requires_grad=True)

    def rollout(u, y0, *weights):
        overrides = {**params, **dict(zip(names, weights))}
        return torch.func.functional_call(model, overrides, (u, y0))

    weights = [params[n].detach().clone().requires_grad_(True) for n in names]
    assert torch.autograd.gradcheck(rollout, (u, y0, *weights), eps=1e-6, atol=1e-7)
