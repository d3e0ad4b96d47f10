"""The init window inside the FMU: parameters set before initialisation, FMU == torch to 1e-9 in float64."""

from __future__ import annotations

import numpy as np
import pytest

from nnfmu.cli import main
from nnfmu.cosim import FmuSimulator, inspect_fmu
from nnfmu.export import build_fmu, casadi_model
from nnfmu.models import EnsembleStepModel, load_model
from nnfmu.window_names import past_element, past_name
from tests.test_model_options import N, past, perturbed
from builtin_networks import ARCHS

pytestmark = pytest.mark.usefixtures("one_thread")


def simulate_fmu(path, u, y0, y_past=None, u_past=None, n_u=2, n_y=3):
    inputs, outputs = [f"u{j + 1}" for j in range(n_u)], [f"y{j + 1}" for j in range(n_y)]
    with FmuSimulator(path, inputs, outputs, 1.0) as sim:
        return sim.simulate(u, y0, y_past, u_past)


def assert_fmu_equals_torch(path, model, u, y0, **window):
    got = simulate_fmu(path, u, y0, window.get("y_past"), window.get("u_past"), model.config.n_u, model.config.n_y)
    expected = model.simulate(u, y0, **window)
    scale = np.abs(expected).max(axis=0)
    np.testing.assert_allclose(got / scale, expected / scale, rtol=0, atol=1e-9)


@pytest.fixture(scope="module")
def fmi2(tmp_path_factory):
    """Per architecture a model with an init window (GRU and TCN in increment mode) and its FMI 2 FMU."""
    folder, built = tmp_path_factory.mktemp("fmus"), {}

    def get(arch: str):
        if arch not in built:
            model = perturbed(arch, init_window=N, increment=arch in ("gru", "tcn"))
            built[arch] = model, build_fmu(casadi_model(model, name=f"w_{arch}"), folder / f"{arch}.fmu")
        return built[arch]

    return get


@pytest.mark.parametrize("arch", ARCHS)
def test_fmi2_window_parameters_give_the_torch_free_run(arch, fmi2):
    model, fmu = fmi2(arch)
    info = inspect_fmu(fmu)
    assert info.init_window == N and past_element("y1", 1) in info.parameters
    rng = np.random.default_rng(3)
    u, y0 = rng.standard_normal((200, 2)), rng.standard_normal(3)
    y_past, u_past = past()
    assert_fmu_equals_torch(fmu, model, u, y0, y_past=y_past, u_past=u_past)
    assert_fmu_equals_torch(fmu, model, u, y0)  # the window not set: the rest state (y0, u0) repeated


def test_fmi3_array_parameters_and_an_ensemble(tmp_path):
    model = EnsembleStepModel.from_members([perturbed("lstm", seed=s, init_window=N) for s in (0, 1)]).eval()
    fmu = build_fmu(casadi_model(model, name="w_ens"), tmp_path / "ens3.fmu", fmi_version=3)
    info = inspect_fmu(fmu)
    assert info.init_window == N and past_name("u2") in info.parameters
    rng = np.random.default_rng(4)
    u, y0 = rng.standard_normal((200, 2)), rng.standard_normal(3)
    y_past, u_past = past(5)
    assert_fmu_equals_torch(fmu, model, u, y0, y_past=y_past, u_past=u_past)


def test_a_partly_set_window_uses_the_rest_state_where_unset(fmi2):
    """NaN (the start value) means "not set": that sample is y0, or the first input."""
    model, fmu = fmi2("gru")
    rng = np.random.default_rng(5)
    u, y0 = rng.standard_normal((50, 2)), rng.standard_normal(3)
    y_past, u_past = past()
    y_nan, u_nan = y_past.copy(), u_past.copy()
    y_nan[:2, 1], u_nan[0, :] = np.nan, np.nan
    y_rest, u_rest = y_past.copy(), u_past.copy()
    y_rest[:2, 1], u_rest[0, :] = y0[1], u[0]
    got = simulate_fmu(fmu, u, y0, y_nan, u_nan)
    np.testing.assert_allclose(got, model.simulate(u, y0, y_past=y_rest, u_past=u_rest), rtol=1e-9, atol=1e-12)
    bad = y_past.copy()
    bad[1, 0] = np.inf
    with pytest.raises(Exception, match="sample 2 .* of the init window y1_past is inf"):
        simulate_fmu(fmu, u, y0, bad, u_past)


def test_train_init_window_20_on_valve_exports_a_settable_fmu(valve_small_dir, valve_small, tmp_path, capsys):
    """Issue 11's check: ``nnfmu train --init-window 20`` -> an FMU whose window fmpy sets; == load_model().simulate."""
    ckpt, fmu = tmp_path / "gru.pt", tmp_path / "gru.fmu"
    assert main(["train", "--data", str(valve_small_dir), "--arch", "gru", "--hidden", "8", "--init-window", "20",
                 "--epochs", "1", "--truncate", "60", "--linear-path", "off", "--quiet", "-o", str(ckpt)]) == 0
    assert "after the init window" in capsys.readouterr().out
    assert main(["export", str(ckpt), "-o", str(fmu)]) == 0
    model = load_model(ckpt)
    u, y = valve_small.test.u[0], valve_small.test.y[0]
    with FmuSimulator(fmu, valve_small.input_names, valve_small.output_names, valve_small.Ts) as sim:
        got = sim.simulate(u[19:], y[19], y[:19], u[:19])
    expected = model.simulate(u[19:], y[19], y_past=y[:19], u_past=u[:19])
    scale = np.abs(expected).max(axis=0)
    np.testing.assert_allclose(got / scale, expected / scale, rtol=0, atol=1e-9)
    assert not np.allclose(got, model.simulate(u[19:], y[19]))  # the window matters
