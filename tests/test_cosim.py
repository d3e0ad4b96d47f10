"""The one scoring path: fmpy co-simulates an FMU on a dataset split, and NRMSE scores it."""

import json
import subprocess
import sys

import numpy as np
import pytest

from fmu_cases import MODELS, built_fmu
from nnfmu.cosim import evaluate, inspect_fmu, simulate_split
from nnfmu.data import Channel, from_arrays, save_dataset
from nnfmu.errors import DataError, DataFileError, SimulationError
from nnfmu.metrics import nrmse

MODEL = MODELS["linear"]  # Ts = 0.01 s, input 'force', outputs 'pos', 'vel'


def _dataset(perturbation: float = 0.0, seed: int = 0, n_traj: int = 3, n: int = 200):
    """Trajectories of the oscillator itself; ``y`` gets a known deterministic error after sample 0."""
    rng = np.random.default_rng(seed)
    us, ys, errs = [], [], []
    for i in range(n_traj):
        u = rng.normal(size=(n + 10 * i, 1))
        y0 = rng.normal(size=2)
        y = MODEL.simulate(u, y0)
        err = perturbation * np.sin(np.arange(len(u))[:, None] * [0.1, 0.23] + i)
        err[0] = 0.0  # the measured y0 starts the simulation
        us.append(u)
        ys.append(y + err)
        errs.append(err)
    ds = from_arrays(Ts=0.01, u_train=us, y_train=ys, u_test=us, y_test=ys,
                     input_names=[Channel("force", "N")], output_names=[Channel("pos", "m"), Channel("vel", "m/s")])
    return ds, errs


def test_known_answer_nrmse():
    ds, errs = _dataset(perturbation=0.05)
    (ev,) = evaluate([built_fmu("linear", 2)], ds)
    # The FMU reproduces the model exactly, so the error is the known perturbation:
    # NRMSE_k = sqrt(mean(err_k^2)) / std(y_k), averaged over outputs, then over trajectories.
    expected = np.mean([np.mean(np.sqrt(np.mean(e ** 2, axis=0)) / y.std(axis=0))
                        for e, y in zip(errs, ds.test.y)])
    assert ev.result.mean == pytest.approx(expected, rel=1e-9)
    assert ev.result.per_output.shape == (3, 2)


@pytest.mark.parametrize("fmi_version", [2, 3])
def test_predictions_equal_the_casadi_free_run(fmi_version):
    ds, _ = _dataset()
    pred = simulate_split(built_fmu("linear", fmi_version), ds, "test")
    for p, u, y in zip(pred, ds.test.u, ds.test.y):
        np.testing.assert_allclose(p, MODEL.simulate(u, y[0]), rtol=1e-12, atol=1e-15)
    assert nrmse(list(ds.test.y), pred).mean < 1e-12


def test_several_fmus_are_scored_in_order_with_names():
    ds, _ = _dataset(perturbation=0.01)
    evs = evaluate([built_fmu("linear", 2), built_fmu("linear_twin", 3)], ds, names=["good", "other"])
    assert [e.name for e in evs] == ["good", "other"]
    assert evs[0].result.mean < evs[1].result.mean  # the twin has other dynamics
    js = evs[0].to_json(ds.output_names)
    assert set(js["per_output"]) == {"pos", "vel"} and js["nrmse"] == pytest.approx(evs[0].result.mean)


def test_input_names_must_match():
    ds, _ = _dataset()
    other = ds.replace(inputs=(Channel("torque", "N.m"),))
    with pytest.raises(DataError, match=r"FMU inputs \['force'\] do not match the dataset's inputs \['torque'\]"):
        evaluate([built_fmu("linear", 2)], other)


def test_sample_time_must_match():
    ds, _ = _dataset()
    with pytest.raises(DataError, match="sample time 0.01 s differs from the dataset's Ts = 0.02 s"):
        simulate_split(built_fmu("linear", 2), ds.replace(Ts=0.02), "test")


def test_dataset_without_test_split():
    ds, _ = _dataset()
    no_test = ds.replace(splits={"train": ds.train})
    with pytest.raises(DataError, match="no 'test' split"):
        evaluate([built_fmu("linear", 2)], no_test)


def test_missing_and_broken_fmu_files(tmp_path):
    with pytest.raises(DataFileError, match="not found"):
        inspect_fmu(tmp_path / "none.fmu")
    (tmp_path / "bad.fmu").write_bytes(b"not a zip")
    with pytest.raises(DataFileError, match="not a readable FMU"):
        inspect_fmu(tmp_path / "bad.fmu")


def test_failing_fmu_reports_its_own_message():
    # y' = y * exp(u) overflows for u = 800: the FMU refuses the step and says why.
    u = np.full((5, 1), 1.0)
    u[2] = 800.0
    y = np.exp(np.arange(5.0))[:, None]
    ds = from_arrays(Ts=0.5, u_train=u, y_train=y, u_test=u, y_test=y, input_names=["u"], output_names=["y"])
    with pytest.raises(SimulationError, match=r"blowup\S*\.fmu: simulation failed.*the FMU said: .*y became inf at t = 1.5 s"):
        simulate_split(built_fmu("blowup", 2), ds, "test")


def test_evaluate_cli_prints_table_writes_json_and_plot(tmp_path):
    ds, errs = _dataset(perturbation=0.02)
    save_dataset(ds, tmp_path / "data")
    fmu = built_fmu("linear", 2)
    run = subprocess.run([sys.executable, "-m", "nnfmu", "evaluate", "--data", str(tmp_path / "data"), str(fmu),
                          "--json", str(tmp_path / "scores.json"), "--plots", str(tmp_path / "plots")],
                         capture_output=True, text=True)
    assert run.returncode == 0, run.stderr
    doc = json.loads((tmp_path / "scores.json").read_text())
    (model,) = doc["models"]
    assert model["name"] == fmu.stem and np.isfinite(model["nrmse"])
    assert f"{model['nrmse']:.4f}" in run.stdout and "pos" in run.stdout
    # RMSE in each output's unit and fit % beside NRMSE, per model, output and trajectory
    rmse = np.array([np.sqrt(np.mean(e ** 2, axis=0)) for e in errs])  # the known error, (n_traj, n_y)
    assert model["fit_percent"] == pytest.approx(100 * (1 - model["nrmse"]), rel=1e-12)
    for j, (name, unit) in enumerate((("pos", "m"), ("vel", "m/s"))):
        out = model["outputs"][name]
        assert out["unit"] == unit and out["rmse"] == pytest.approx(rmse[:, j].mean(), rel=1e-6)
        assert out["fit_percent"] == pytest.approx(100 * (1 - out["nrmse"]), rel=1e-12)
        assert f"{name} [{unit}]" in run.stdout and f"{out['rmse']:.4g}" in run.stdout
    assert [t["index"] for t in model["trajectories"]] == [0, 1, 2]
    assert model["trajectories"][1]["outputs"]["vel"]["rmse"] == pytest.approx(rmse[1, 1], rel=1e-6)
    assert "fit %" in run.stdout and f"{model['fit_percent']:.2f}" in run.stdout
    png = tmp_path / "plots" / "test_trajectory.png"
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    bad = subprocess.run([sys.executable, "-m", "nnfmu", "evaluate", "--data", str(tmp_path / "data"),
                          str(tmp_path / "missing.fmu")], capture_output=True, text=True)
    assert bad.returncode == 2 and "missing.fmu not found" in bad.stderr
    out = subprocess.run([sys.executable, "-m", "nnfmu", "evaluate", "--data", str(tmp_path / "data"), str(fmu),
                          "-o", str(tmp_path / "all")], capture_output=True, text=True)
    assert out.returncode == 0, out.stderr
    assert sorted(p.name for p in (tmp_path / "all").iterdir()) == ["scores.json", "test_trajectory.png"]


def test_plot_axes_follow_the_measurement_when_a_model_drifts_away(tmp_path, monkeypatch):
    """A diverging baseline must not flatten the others: axes keep to the measured range, the label says so."""
    import matplotlib.figure

    from nnfmu.cosim import Evaluation
    from nnfmu.plots import plot_trajectory

    ds, _ = _dataset(perturbation=0.02, n_traj=1)
    y = ds.test.y[0]
    good, drift = y * 1.01, y + 1e3 * np.linspace(0, 1, len(y))[:, None]
    evs = [Evaluation(name, tmp_path / f"{name}.fmu", nrmse(y, p), [p]) for name, p in (("good", good), ("drift", drift))]
    saved = []
    real_savefig = matplotlib.figure.Figure.savefig
    monkeypatch.setattr(matplotlib.figure.Figure, "savefig",
                        lambda fig, *a, **k: (saved.append(fig), real_savefig(fig, *a, **k))[1])
    png = plot_trajectory(ds, evs, tmp_path / "fig.png", index=0)
    assert png.is_file() and len(saved) == 1
    fig = saved[0]
    labels = [t.get_text() for t in fig.legends[0].get_texts()]
    assert any(t.startswith("good (") and "leaves" not in t for t in labels)
    assert any(t.startswith("drift (") and t.endswith(", leaves the axes)") for t in labels)
    output_axes = fig.axes[-2:]  # pos, vel below the input
    for j, ax in enumerate(output_axes):
        lo, hi = ax.get_ylim()
        width = y[:, j].max() - y[:, j].min()
        assert lo == pytest.approx(y[:, j].min() - 0.5 * width) and hi == pytest.approx(y[:, j].max() + 0.5 * width)
