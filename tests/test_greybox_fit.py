"""Grey-box identification (nnfmu fit): the slider's m and d recovered from data of its own structure.

The data come from the slider itself (true m = 1.0 kg, d = 2.0 N.s/m, the friction curve known), a few
short records from rest under random step forces, with white noise on the position; the fit starts far
from the truth (m = 1.6, d = 1.3) and must land within two of its own standard errors.
"""

from __future__ import annotations

import json

import casadi as ca
import fmpy
import fmpy.validation
import numpy as np
import pytest

from nnfmu.cli import main
from nnfmu.cosim import FmuSimulator
from nnfmu.data import from_arrays, save_dataset
from nnfmu.greybox import FitConfig, fit_greybox, load_fit, save_fit, standard_errors
from nnfmu.greybox.problem import build_problem, cut_windows
from nnfmu.greybox.solvers import Tracker
from nnfmu.physics import slider_system, system_from_document
from physics_sim import simulate_states

TRUE = {"m": 1.0, "d": 2.0}
NOISE_M = 2e-3  # position noise, m (the records move by about 0.5 m)


def _record(system, rng, n: int) -> tuple[np.ndarray, np.ndarray]:
    """One record from rest at a random position under held random forces: u (n, 1) N, y (n, 1) m."""
    holds = rng.integers(20, 80, size=n)
    u = np.repeat(rng.uniform(-6, 6, size=n), holds)[:n, None]
    x = simulate_states(system, [rng.uniform(-1, 1), 0.0], u[:-1])
    return u, x[:, :1] + NOISE_M * rng.standard_normal((n, 1))


@pytest.fixture(scope="module")
def data(tmp_path_factory):
    system = slider_system()
    rng = np.random.default_rng(3)
    train = [_record(system, rng, 300) for _ in range(4)]
    test = [_record(system, rng, 600)]
    ds = from_arrays(Ts=system.Ts, u_train=[u for u, _ in train], y_train=[y for _, y in train],
                     u_test=[u for u, _ in test], y_test=[y for _, y in test],
                     input_names=[{"name": "F", "unit": "N"}], output_names=[{"name": "pos", "unit": "m"}])
    return ds, save_dataset(ds, tmp_path_factory.mktemp("greybox") / "slider")


@pytest.fixture(scope="module")
def fitted(data):
    config = FitConfig(free=("m", "d"), start={"m": 1.6, "d": 1.3}, window=100)
    return fit_greybox(slider_system(), data[0], config, score_test=True)


def test_the_fit_recovers_m_and_d_within_two_standard_errors(fitted):
    rows = fitted.report["parameters"]
    for name, truth in TRUE.items():
        value, se = rows[name]["value"], rows[name]["std_error"]
        assert 0 < se < 0.05 * truth, (name, se)
        assert abs(value - truth) <= 2 * se, (name, value, se)
    assert rows["m"]["unit"] == "kg" and rows["d"]["unit"] == "N.s/m"
    assert fitted.system.free_parameters == ("m", "d")
    scores = fitted.report["scores"]
    assert set(scores) == {"train", "test"} and scores["test"]["nrmse"] < 0.05
    assert {"rmse", "fit_percent"} <= set(scores["test"]["outputs"]["pos"])


def test_standard_errors_are_the_parameter_block_of_the_whole_gauss_newton_covariance(data):
    system, ds = slider_system(), data[0]
    windows = cut_windows(ds.train.u, ds.train.y, 150)
    p = system.parameter_values()
    problem = build_problem(system, windows, np.array([0, 1]), p, p[:2], np.array([0.3]), n_sub=4)
    z = problem.pack(p[:2] * [1.1, 0.9], np.column_stack([windows.y[:, 0, 0], np.zeros(windows.n_w)]))
    r, J = problem.evaluate(z), problem.jacobian(z)
    zs = ca.MX.sym("z", problem.n_z)
    exact = ca.Function("J", [zs], [ca.jacobian(problem.residuals(zs), zs)])(z).full()
    np.testing.assert_allclose(J, exact, rtol=1e-9, atol=1e-12)  # forward sensitivities = CasADi's own AD
    cost = 0.5 * r @ r
    covariance = 2 * cost / (len(r) - problem.n_z) * np.linalg.inv(J.T @ J)
    np.testing.assert_allclose(standard_errors(problem, z, cost), p[:2] * np.sqrt(np.diag(covariance)[:2]),
                               rtol=1e-8)


def test_nnfmu_fit_prints_the_estimates_and_writes_a_file_that_reloads(data, fitted, tmp_path, capsys):
    out = tmp_path / "fit.json"
    assert main(["fit", "slider", "--data", str(data[1]), "--free", "m,d", "--start", "m=1.6,d=1.3",
                 "--window", "100", "--quiet", "--report-test", "-o", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "std error" in printed and "test: NRMSE" in printed
    assert "identifiability:" not in printed and "solver: converged" in printed  # well posed: no flag
    doc = json.loads(out.read_text())
    assert doc["format"] == "nnfmu-greybox-fit/1" and set(doc["fit"]["parameters"]) == {"m", "d"}
    again = system_from_document(doc["physics"])
    np.testing.assert_allclose(again.parameter_values(), fitted.system.parameter_values(), rtol=1e-6)
    system, report = load_fit(out)
    assert system.free_parameters == ("m", "d") and report["parameters"]["m"]["std_error"] > 0


def test_the_fit_exports_to_an_fmu_that_simulates_as_the_fitted_model(data, fitted, tmp_path):
    ds = data[0]
    out = save_fit(tmp_path / "fit.json", fitted.system, fitted.report)
    fmu = tmp_path / "fit.fmu"
    assert main(["export", str(out), "-o", str(fmu)]) == 0
    assert fmpy.validation.validate_fmu(str(fmu)) == []
    assert fmpy.read_model_description(str(fmu)).modelExchange is not None
    system = fitted.system
    u, y = ds.test.u[0], ds.test.y[0]
    with FmuSimulator(fmu, ["F"], ["pos"], system.Ts) as sim:
        y_fmu = sim.simulate(u, y[0])
    x = simulate_states(system, np.asarray(system.init_state(y[0], u[0], system.parameter_values())).ravel(), u[:-1])
    np.testing.assert_allclose(y_fmu[1:, 0], x[1:, 0], rtol=1e-9, atol=1e-9)


def test_several_starts_are_each_reported_and_the_best_is_kept(data):
    fit = fit_greybox(slider_system(), data[0], FitConfig(free=("d",), window=300, starts=3, seed=1,
                                                          max_evaluations=20))
    runs = fit.report["starts"]
    assert len(runs) == 3 and runs[0]["start"] == {"d": 2.0} and runs[1]["start"] != runs[2]["start"]
    assert fit.report["cost"] == min(r["cost"] for r in runs)
    assert any("limit of 20 evaluations" in note for run in runs for note in run["notes"])


def test_a_diverged_evaluation_keeps_the_best_finite_point():
    tracker = Tracker()
    tracker.see(np.array([1.0]), np.array([2.0]))
    tracker.see(np.array([2.0]), np.array([np.nan]))
    tracker.see(np.array([3.0]), np.array([3.0]))
    assert tracker.best_z.tolist() == [1.0] and tracker.best_cost == 2.0 and tracker.non_finite == 1


@pytest.mark.parametrize("extra, words", [
    (["--free", "m,mass"], "free parameter mass: no such parameter"),
    (["--fixed", "nope"], "fixed parameter nope"),
    (["--free", "m", "--bounds", "m=2:3"], "exclude its start 1"),
    (["--free", "m", "--bounds", "m=2"], "give LO:HI"),
    (["--free", "m", "--start", "m=0"], "at the start parameters gives NaN or Inf"),
    (["--free", "m", "--window", "1"], "window must be a whole number >= 2"),
])
def test_bad_fit_input_is_one_line_status_2_and_nothing_written(data, tmp_path, capsys, extra, words):
    out = tmp_path / "fit.json"
    assert main(["fit", "slider", "--data", str(data[1]), "--quiet", "-o", str(out), *extra]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and words in err, err
    assert not out.exists()


def test_a_dataset_that_is_not_the_models_is_refused(data, tmp_path, capsys):
    ds = data[0]
    other = save_dataset(ds.replace(inputs=({"name": "force", "unit": "N"},)), tmp_path / "renamed")
    out = tmp_path / "fit.json"
    assert main(["fit", "slider", "--data", str(other), "--quiet", "-o", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert "the dataset's inputs (force [N]) are not the model's (F [N])" in err and len(err.splitlines()) == 1
    assert not out.exists()


def test_export_of_a_json_that_is_not_a_fit_is_one_line(tmp_path, capsys):
    bogus = tmp_path / "x.json"
    bogus.write_text(json.dumps({"format": "something"}))
    assert main(["export", str(bogus), "-o", str(tmp_path / "x.fmu")]) == 2
    assert "is not a grey-box fit" in capsys.readouterr().err and not (tmp_path / "x.fmu").exists()


def test_a_bound_holds_the_estimate_and_is_reported(data):
    fit = fit_greybox(slider_system(), data[0], FitConfig(free=("d",), bounds={"d": (2.5, 4.0)}, start={"d": 3.0},
                                                          window=300, max_evaluations=30))
    row = fit.report["parameters"]["d"]
    assert 2.5 <= row["value"] < 2.5 + 1e-6 and row["at_bound"] and (row["min"], row["max"]) == (2.5, 4.0)
    d = next(v for v in fit.system.parameters if v.name == "d")
    assert (d.min, d.max) == (2.5, 4.0)
