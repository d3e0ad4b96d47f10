"""The grey-box windows: folded sub-step sensitivities, compiled window Functions, a spread of windows.

A model with many RK4 sub-steps (the arm's 50) has its sensitivities carried one sub-step at a time; the
compiled C of the window Functions gives the same residuals and Jacobian as CasADi's virtual machine; and
``max_windows`` fits on windows spread over the whole training split, saying so.
"""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from nnfmu.cli import main
from nnfmu.data import from_arrays, save_dataset
from nnfmu.errors import ConfigError
from nnfmu.greybox import FitConfig, fit_greybox
from nnfmu.greybox.problem import build_problem, cut_windows
from nnfmu.greybox.window import _sub_sensitivity, sensitivity_step
from nnfmu.physics import slider_system
from nnfmu.physics.rk4 import UNROLL_MAX
from physics_sim import simulate_states


@pytest.fixture(scope="module")
def slider_data():
    """Four 200-sample records of the slider under held random forces, from rest: u (N), y (m)."""
    system, rng = slider_system(), np.random.default_rng(5)
    us, ys = [], []
    for _ in range(4):
        u = np.repeat(rng.uniform(-6, 6, size=10), 20)[:, None]
        x = simulate_states(system, [rng.uniform(-1, 1), 0.0], u[:-1])
        us.append(u)
        ys.append(x[:, :1] + 1e-3 * rng.standard_normal((200, 1)))
    return from_arrays(Ts=system.Ts, u_train=us, y_train=ys, u_test=us[:1], y_test=ys[:1],
                       input_names=[{"name": "F", "unit": "N"}], output_names=[{"name": "pos", "unit": "m"}])


def test_folded_sub_step_sensitivities_equal_the_unrolled_ones():
    system = slider_system()
    select = np.eye(len(system.parameters))[:, :2]
    n_sub = UNROLL_MAX + 4  # folded, one sub-step's SX sensitivity at a time
    folded, unrolled = sensitivity_step(system, n_sub, select), _sub_sensitivity(system, system.Ts, n_sub, select)
    assert folded.is_a("MXFunction") and unrolled.is_a("SXFunction")
    rng = np.random.default_rng(0)
    x, S = np.array([0.3, -0.8]), rng.standard_normal((2, 4))
    for a, b in zip(folded(x, S, [2.5], system.parameter_values()), unrolled(x, S, [2.5], system.parameter_values())):
        np.testing.assert_allclose(np.asarray(a), np.asarray(b), rtol=1e-12, atol=1e-14)


def test_compiled_windows_give_the_virtual_machines_residuals_and_jacobian(slider_data):
    system = slider_system()
    windows = cut_windows(slider_data.train.u, slider_data.train.y, 50)
    p = system.parameter_values()
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # a fallback to the virtual machine ("runs uncompiled") fails the test
        problems = [build_problem(system, windows, np.array([0, 1]), p, p[:2], np.array([0.3]),
                                  n_sub=UNROLL_MAX + 2, compile=compile) for compile in (False, True)]
    z = problems[0].pack(p[:2] * [1.2, 0.8], np.column_stack([windows.y[:, 0, 0], np.zeros(windows.n_w)]))
    vm, c = problems
    np.testing.assert_allclose(c.evaluate(z), vm.evaluate(z), rtol=1e-12, atol=1e-14)
    for a, b in zip(c.blocks(z), vm.blocks(z)):
        np.testing.assert_allclose(a, b, rtol=1e-11, atol=1e-13)
    assert np.abs(vm.evaluate(z)).max() > 0.1  # the start is off the truth: a residual worth matching


def test_max_windows_fits_on_a_spread_of_the_windows_and_says_so(slider_data, tmp_path, capsys):
    config = FitConfig(free=("m", "d"), start={"m": 1.3, "d": 1.6}, window=40, max_windows=6, max_evaluations=30)
    fit = fit_greybox(slider_system(), slider_data, config)
    assert fit.report["windows"] == 6 and fit.report["windows_in_split"] == 20
    assert fit.report["compiled"] is False  # the slider is small: "auto" leaves it in the virtual machine
    assert abs(fit.report["parameters"]["m"]["value"] - 1.0) < 0.1  # six windows still identify it
    folder = save_dataset(slider_data, tmp_path / "slider")
    assert main(["fit", "slider", "--data", str(folder), "--free", "m,d", "--window", "40", "--max-windows", "6",
                 "--max-evaluations", "5", "--quiet", "-o", str(tmp_path / "fit.json")]) == 0
    assert "6 windows (of 20, spread over the training split)" in capsys.readouterr().out


@pytest.mark.parametrize("bad", [{"max_windows": 0}, {"compile": "yes"}])
def test_bad_window_options_are_refused(bad):
    with pytest.raises(ConfigError):
        FitConfig(**bad)


def test_a_large_problem_takes_a_sparse_jacobian_equal_to_the_dense_one_and_fits_the_same(slider_data, monkeypatch):
    from nnfmu.greybox import problem as problem_module

    system = slider_system()
    windows = cut_windows(slider_data.train.u, slider_data.train.y, 50)
    p = system.parameter_values()
    problem = build_problem(system, windows, np.array([0, 1]), p, p[:2], np.array([0.3]), n_sub=4)
    z = problem.pack(p[:2] * [1.2, 0.8], np.column_stack([windows.y[:, 0, 0], np.zeros(windows.n_w)]))
    dense = problem.jacobian(z)
    assert problem.dense and isinstance(dense, np.ndarray)
    config = FitConfig(free=("m", "d"), start={"m": 1.3, "d": 1.6}, window=50, max_evaluations=40)
    exact = fit_greybox(system, slider_data, config).report["parameters"]
    monkeypatch.setattr(problem_module, "DENSE_MAX_WORK", 0)  # as for the arm's 17,100 x 1818 Jacobian
    assert not problem.dense
    np.testing.assert_allclose(problem.jacobian(z).toarray(), dense, rtol=0, atol=0)
    sparse = fit_greybox(system, slider_data, config).report["parameters"]  # trf's steps by LSMR
    for name in ("m", "d"):
        assert abs(sparse[name]["value"] - exact[name]["value"]) < 0.2 * exact[name]["std_error"], name


def test_compiled_scores_equal_the_virtual_machines(slider_data):
    from nnfmu.greybox import score_system

    system = slider_system()
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # the compiled step, not a fallback to the virtual machine
        vm, compiled = (score_system(system, slider_data, compile=c) for c in (False, True))
    for split in ("train", "test"):
        assert compiled[split]["nrmse"] == pytest.approx(vm[split]["nrmse"], rel=1e-12)
