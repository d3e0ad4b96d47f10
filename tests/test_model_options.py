"""Options every architecture has: the init window, increment mode and ensembles; torch == CasADi for each."""

from __future__ import annotations

import pathlib
import re
import subprocess
import sys

import numpy as np
import pytest
import torch

import nnfmu.models
from nnfmu.errors import ConfigError, ShapeError
from nnfmu.export import casadi_model
from nnfmu.models import EnsembleStepModel, ModelConfig, StepModel
from tests.test_models import N_U, N_Y, make_model, random_io
from builtin_networks import ARCHS

N = 6  # init window
pytestmark = pytest.mark.usefixtures("one_thread")


def perturbed(arch: str, seed: int = 0, **options) -> StepModel:
    """A float64 model whose weights (the encoder's zero-initialised last layer too) are all non-trivial."""
    model = make_model(arch, seed=seed, **options)
    with torch.no_grad():
        for p in model.parameters():
            p.add_(0.3 * torch.randn_like(p))
    if model.config.increment:
        model.set_increment_scale([0.05, 0.02, 0.3])
    return model


def past(seed: int = 2, n: int = N - 1) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    return rng.standard_normal((n, N_Y)), rng.standard_normal((n, N_U))


def np_io(steps: int) -> tuple[np.ndarray, np.ndarray]:
    """One trajectory's inputs (steps, n_u) and outputs (steps, n_y) as numpy arrays."""
    u, y = random_io(1, steps)
    return u[0].numpy(), y[0].numpy()


def assert_casadi_equals_torch(model: StepModel, u, y0, **window):
    expected = model.simulate(u, y0, **window)
    got = casadi_model(model).simulate(u, y0, **window)
    scale = np.abs(expected).max(axis=0)
    np.testing.assert_allclose(got / scale, expected / scale, rtol=0, atol=1e-9)


@pytest.mark.parametrize("arch", ARCHS)
@pytest.mark.parametrize("increment", [False, True])
def test_init_window_and_increment_export_to_casadi_exactly(arch, increment):
    model = perturbed(arch, init_window=N, increment=increment)
    u, y = np_io(300)
    y_past, u_past = past()
    assert_casadi_equals_torch(model, u, y[0], y_past=y_past, u_past=u_past)
    assert_casadi_equals_torch(model, u, y[0])  # no window given: the rest state


@pytest.mark.parametrize("arch", ARCHS)
def test_without_a_window_the_plant_is_at_rest(arch):
    model = perturbed(arch, init_window=N)
    u, y = np_io(30)
    rest = (np.tile(y[0], (N - 1, 1)), np.tile(u[0], (N - 1, 1)))
    np.testing.assert_array_equal(model.simulate(u, y[0]), model.simulate(u, y[0], y_past=rest[0], u_past=rest[1]))
    assert not np.allclose(model.simulate(u, y[0]), model.simulate(u, y[0], y_past=past()[0], u_past=past()[1]))


@pytest.mark.parametrize("arch", ["mlp", "tcn"])
def test_window_models_start_from_the_measured_window(arch):
    """MLP/TCN: after an init window their first prediction is the teacher-forced one at that sample."""
    model = perturbed(arch, init_window=20)
    u, y = random_io(1, 40)
    k = 19  # the window is samples 0..19; the free run starts at sample 19
    with torch.no_grad():
        forced = model(u, y[:, 0], y)[:, k + 1]
        free = model(u[:, k:], y[:, k], y_past=y[:, :k], u_past=u[:, :k])[:, 1]
    torch.testing.assert_close(free, forced, rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize("arch", ["rnn", "lstm", "gru"])
def test_a_fresh_encoder_gives_the_zero_hidden_state(arch):
    plain, windowed = make_model(arch), make_model(arch, init_window=N)
    windowed.load_state_dict({**windowed.state_dict(), **plain.state_dict()})
    u, y = np_io(30)
    y_past, u_past = past()
    np.testing.assert_array_equal(windowed.simulate(u, y[0], y_past=y_past, u_past=u_past), plain.simulate(u, y[0]))


@pytest.mark.parametrize("arch", ARCHS)
def test_fused_teacher_forcing_with_window_and_increment_equals_the_step_loop(arch):
    model = perturbed(arch, init_window=N, increment=True)
    un, yn = random_io(2, 30)
    y_past, u_past = (torch.as_tensor(np.stack([a, a + 1])) for a in past())
    with torch.no_grad():
        x0 = model.init_window_norm(*model._window(yn[:, 0], un[:, 0], (y_past, u_past)))
        fused = model.rollout_normalised(un, yn[:, 0], yn, (y_past, u_past))[:, 1:]
        generic = StepModel.teacher_forced_norm(model, un, yn, x0)
    torch.testing.assert_close(fused, generic, rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize("arch", ARCHS)
def test_increment_mode_shifts_the_response_with_the_output(arch):
    """Translation invariance: shifting y0 and the window by c shifts the whole free run by c."""
    model = perturbed(arch, init_window=N, increment=True)
    u, y = np_io(60)
    y_past, u_past = past()
    shift = np.array([3.0, -7.0, 0.5])
    base = model.simulate(u, y[0], y_past=y_past, u_past=u_past)
    moved = model.simulate(u, y[0] + shift, y_past=y_past + shift, u_past=u_past)
    np.testing.assert_allclose(moved - shift, base, rtol=0, atol=1e-9)


def test_increment_scale_is_the_std_of_the_data_increments():
    from nnfmu.data import Trajectories
    from nnfmu.training.increments import increment_std, prepare_increment

    y = np.cumsum(np.random.default_rng(0).standard_normal((500, N_Y)) * [1.0, 0.1, 2.0], axis=0)
    traj = Trajectories((np.zeros((500, N_U)),), (y,))
    model = make_model("gru", increment=True)
    prepare_increment(model, traj)
    np.testing.assert_allclose(model.increment_scale.numpy() * model.y_std.numpy(), increment_std(traj))
    np.testing.assert_allclose(increment_std(traj), np.diff(y, axis=0).std(0))


@pytest.mark.parametrize("arch", ARCHS)
def test_ensemble_feeds_the_members_mean_back_and_exports_as_one_model(arch):
    members = [perturbed(arch, seed=s, init_window=N) for s in range(3)]
    ensemble = EnsembleStepModel.from_members(members).eval()
    u, y = np_io(200)
    y_past, u_past = past()
    assert_casadi_equals_torch(ensemble, u, y[0], y_past=y_past, u_past=u_past)
    first = np.mean([m.simulate(u[:2], y[0])[1] for m in members], axis=0)  # one step: the members' mean
    np.testing.assert_allclose(ensemble.simulate(u[:2], y[0])[1], first, rtol=1e-12)
    same = EnsembleStepModel.from_members([members[0], members[0]])  # identical members: the member itself
    np.testing.assert_allclose(same.simulate(u, y[0]), members[0].simulate(u, y[0]), atol=1e-12)


def test_bad_windows_and_options_say_what_to_do():
    model = make_model("gru", init_window=N)
    with pytest.raises(ShapeError, match=r"y_past has shape \(1, 3, 3\), expected \(1, 5, 3\)"):
        model(torch.zeros(1, 5, N_U, dtype=torch.float64), torch.zeros(1, N_Y, dtype=torch.float64),
              y_past=torch.zeros(1, 3, N_Y, dtype=torch.float64), u_past=torch.zeros(1, 3, N_U, dtype=torch.float64))
    with pytest.raises(ShapeError, match="give both y_past and u_past"):
        model.simulate(np.zeros((5, N_U)), np.zeros(N_Y), y_past=np.zeros((N - 1, N_Y)))
    with pytest.raises(ShapeError, match="init_window 1"):
        make_model("gru").simulate(np.zeros((5, N_U)), np.zeros(N_Y), y_past=np.zeros((2, N_Y)),
                                   u_past=np.zeros((2, N_U)))
    with pytest.raises(ConfigError, match="needs skip=True"):
        ModelConfig(arch="mlp", n_u=1, n_y=1, increment=True, skip=False)
    with pytest.raises(ShapeError, match="positive integer"):
        ModelConfig(arch="mlp", n_u=1, n_y=1, init_window=0)
    with pytest.raises(ShapeError, match="differ in increment"):  # a GRU with an LSTM is fine, not two modes
        EnsembleStepModel.from_members([make_model("gru"), make_model("lstm", increment=True)])


def test_models_never_import_the_packages_above_them():
    """models/ stays below hybrid/: a hybrid registers itself and a stored hybrid config still loads."""
    code = ("import sys, nnfmu.models as m; assert 'nnfmu.hybrid' not in sys.modules; "
            "print(type(m.ModelConfig.from_dict({'arch': 'hybrid', 'n_u': 2, 'n_y': 2, 'physics': 'valve'})).__name__)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.split() == ["HybridConfig"]
    upward = re.compile(r"^\s*(from|import) nnfmu\.(hybrid|export|study|cli)\b", re.MULTILINE)
    sources = pathlib.Path(nnfmu.models.__file__).parent.glob("*.py")
    assert not [p.name for p in sources if upward.search(p.read_text())]
