"""`nnfmu.from_benchmark` on the nonlinear_benchmarks package's own Input_output_data objects (no download)."""

import json

import numpy as np
import pytest

nonlinear_benchmarks = pytest.importorskip("nonlinear_benchmarks", reason="the extra 'benchmarks' is not installed")
from nonlinear_benchmarks import Input_output_data  # noqa: E402
from nonlinear_benchmarks.error_metrics import RMSE, fit_index  # noqa: E402

import nnfmu  # noqa: E402
from nnfmu.data import load_dataset, save_dataset  # noqa: E402
from nnfmu.errors import DataError  # noqa: E402

pytestmark = pytest.mark.usefixtures("one_thread")
TS = 4.0


def _tank(n: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """A first-order tank, y[k+1] = 0.9 y[k] + 0.1 u[k]: learnable in a few epochs."""
    u = np.random.default_rng(seed).uniform(0.0, 5.0, size=n)
    y = np.zeros(n)
    for k in range(n - 1):
        y[k + 1] = 0.9 * y[k] + 0.1 * u[k]
    return u, y


def _benchmark_pair():
    """What nonlinear_benchmarks.Cascaded_Tanks() returns: (train, test) with a 50-sample init window on test."""
    train = Input_output_data(*_tank(400, 0), sampling_time=TS, name="train tanks")
    test = Input_output_data(*_tank(300, 1), sampling_time=TS, name="test tanks")
    test.state_initialization_window_length = 50
    return train, test


@pytest.fixture(scope="module")
def tanks(tmp_path_factory):
    ds = nnfmu.from_benchmark(_benchmark_pair(), inputs=[{"name": "u", "unit": "V"}],
                              outputs=[{"name": "y", "unit": "V"}], name="Cascaded_Tanks")
    return ds, save_dataset(ds, tmp_path_factory.mktemp("bench") / "tanks")


def test_benchmark_pair_becomes_a_dataset_with_its_init_window(tanks):
    ds, folder = tanks
    assert ds.Ts == TS and ds.input_names == ["u"] and ds.outputs[0].unit == "V"
    assert ds.train.lengths.tolist() == [400] and ds.test.lengths.tolist() == [300]
    assert ds.init_window == 50 and ds.source["benchmark"] == "Cascaded_Tanks"
    assert json.loads((folder / "meta.json").read_text())["init_window"] == 50
    assert load_dataset(folder).init_window == 50


def test_lists_of_records_and_2d_arrays():
    records = [Input_output_data(*_tank(100, s), sampling_time=TS).atleast_2d() for s in range(3)]
    tests = [Input_output_data(*_tank(80, s), sampling_time=TS, state_initialization_window_length=w)
             for s, w in ((5, 10), (6, 20))]
    ds = nnfmu.from_benchmark(records, tests, valid=records[0])
    assert (ds.train.n_traj, ds.valid.n_traj, ds.test.n_traj) == (3, 1, 2)
    assert ds.input_names == ["u1"] and ds.init_window == 20  # the largest window of the test records
    no_window = nnfmu.from_benchmark(records, records[0])
    assert no_window.init_window is None


def test_refusals_say_what_to_give():
    train, test = _benchmark_pair()
    with pytest.raises(DataError, match="no test data"):
        nnfmu.from_benchmark(train)
    odd = Input_output_data(*_tank(50, 3), sampling_time=1.0)
    with pytest.raises(DataError, match="sample times differ by more than 0.0001"):
        nnfmu.from_benchmark(train, odd)
    discrete = Input_output_data(*_tank(50, 3))
    with pytest.raises(DataError, match="discrete-time .* give Ts"):
        nnfmu.from_benchmark(discrete, discrete)
    assert nnfmu.from_benchmark(discrete, discrete, Ts=0.5).Ts == 0.5


def test_the_dataset_trains_and_scores_like_the_benchmark_package(tanks):
    ds, _ = tanks
    result = nnfmu.train(ds, nnfmu.ModelConfig(arch="gru", n_u=1, n_y=1, hidden=8),
                         nnfmu.TrainConfig(epochs=3, batch_size=1, truncate=50, lr=1e-2, patience=0))
    assert result.test is not None and np.isfinite(result.test.mean)
    assert result.history[-1]["best_valid_nrmse"] < result.history[0]["valid_nrmse"]  # it learned something
    predicted = result.model.simulate(ds.test.u[0], ds.test.y[0][0])
    scores = nnfmu.nrmse(ds.test.y[0], predicted)
    # RMSE (in the output's unit) and fit % agree with the benchmark package's own metrics
    assert scores.rmse[0, 0] == pytest.approx(float(RMSE(ds.test.y[0], predicted)[0]), rel=1e-12)
    assert scores.fit == pytest.approx(float(fit_index(ds.test.y[0], predicted)[0]), rel=1e-12)


def test_cli_imports_a_named_benchmark(tmp_path, monkeypatch, capsys):
    from nnfmu.cli import main

    calls = []

    def fake(dir_placement=None, **kwargs):  # the package's download is replaced, its data objects are real
        calls.append(dir_placement)
        return _benchmark_pair()

    monkeypatch.setattr(nonlinear_benchmarks, "Cascaded_Tanks", fake)
    assert main(["import", "nonlinear-benchmark", "Cascaded_Tanks", "-o", str(tmp_path / "d"), "--units", "u1=V",
                 "--valid-fraction", "0.25", "--data-dir", str(tmp_path)]) == 0
    ds = load_dataset(tmp_path / "d")
    assert calls == [str(tmp_path)] and ds.init_window == 50 and ds.inputs[0].unit == "V"
    assert ds.train.lengths.tolist() == [300] and ds.valid.lengths.tolist() == [100]
    assert "init window: the first 50 samples" in capsys.readouterr().out
    assert main(["import", "nonlinear-benchmark", "Tanks", "-o", str(tmp_path / "e")]) == 2
    assert "unknown benchmark 'Tanks'; choose one of Cascaded_Tanks" in capsys.readouterr().err


def test_cli_names_the_channels_takes_ts_and_records_that_agree_to_1e_4(tmp_path, monkeypatch, capsys):
    from nnfmu.cli import main

    def fake(dir_placement=None, **kwargs):  # like EMPS: the records' sampling times differ by 0.0024 %
        train, test = _benchmark_pair()
        test.sampling_time = TS * (1 + 2.4e-5)
        return train, test

    monkeypatch.setattr(nonlinear_benchmarks, "Silverbox", fake)
    assert main(["import", "nonlinear-benchmark", "Silverbox", "-o", str(tmp_path / "d")]) == 0
    ds = load_dataset(tmp_path / "d")
    assert ds.input_names == ["u1"] and ds.output_names == ["y1"] and ds.Ts == TS  # the training records' Ts
    assert main(["import", "nonlinear-benchmark", "Silverbox", "--inputs", "u", "--outputs", "y", "--Ts", "2",
                 "-o", str(tmp_path / "e")]) == 0
    ds = load_dataset(tmp_path / "e")
    assert ds.input_names == ["u"] and ds.output_names == ["y"] and ds.Ts == 2.0 and ds.source["name"] == "e"
    assert main(["import", "nonlinear-benchmark", "Silverbox", "--inputs", "u=3", "-o", str(tmp_path / "f")]) == 2
    assert "--inputs: for nonlinear-benchmark it names the channels" in capsys.readouterr().err
    assert main(["import", "robot-benchmark", "r.mat", "--Ts", "2", "-o", str(tmp_path / "f")]) == 2
    assert "robot-benchmark takes one FILE and none of --Ts" in capsys.readouterr().err


def test_the_extracted_files_in_data_dir_are_used_without_their_archive(tmp_path, monkeypatch):
    """Issue 37, item 9: with SilverboxFiles/*.mat extracted in --data-dir but no SilverboxFiles.zip, the package
    downloaded again (and failed offline)."""
    import scipy.io

    from nnfmu.cli import main

    load = nonlinear_benchmarks.Silverbox

    def no_download(*args, **kwargs):
        raise AssertionError("the benchmark was downloaded although its files are in --data-dir")

    monkeypatch.setitem(load.__globals__, "cashed_download", no_download)
    folder = tmp_path / "Silverbox" / "SilverboxFiles"
    folder.mkdir(parents=True)
    v1 = np.sin(np.arange(127_500) * 0.01)[None, :]
    for name in ("SNLS80mV.mat", "Schroeder80mV.mat"):
        scipy.io.savemat(folder / name, {"V1": v1, "V2": 0.5 * v1})
    assert main(["import", "nonlinear-benchmark", "Silverbox", "--data-dir", str(tmp_path),
                 "-o", str(tmp_path / "sb")]) == 0
    assert load_dataset(tmp_path / "sb").Ts == pytest.approx(1 / 610.35)
    assert sorted(p.name for p in (tmp_path / "Silverbox").iterdir()) == ["SilverboxFiles"]  # nothing downloaded
