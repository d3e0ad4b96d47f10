"""`nnfmu import csv|mat|npz` and `nnfmu.load_files`: columns, splits, sample time, resampling, refusals."""

import subprocess
import sys

import numpy as np
import pytest
import scipy.io

from nnfmu.data import from_arrays, load_csv, load_dataset, load_files, save_dataset
from nnfmu.data.resample import decimate
from nnfmu.errors import DataError

NO_TEST = "no test split: every model is scored on held-out test data"


def _nnfmu(*args):
    return subprocess.run([sys.executable, "-m", "nnfmu", *map(str, args)], capture_output=True, text=True)


def _tanks_csv(path, n=120, seed=0):
    """One CSV in the layout of the Cascaded Tanks files: estimation and validation records side by side."""
    rng = np.random.default_rng(seed)
    cols = {"uEst": rng.normal(size=n), "uVal": rng.normal(size=n) + 3.0}
    cols["yEst"] = np.cumsum(cols["uEst"]) * 0.1
    cols["yVal"] = np.cumsum(cols["uVal"]) * 0.1
    rows = ["uEst,uVal,yEst,yVal"] + [",".join(repr(float(cols[k][i])) for k in cols) for i in range(n)]
    path.write_text("\n".join(rows) + "\n")
    return cols


def test_cli_reads_per_split_columns_into_different_splits(tmp_path):
    cols = _tanks_csv(tmp_path / "tanks.csv")
    run = _nnfmu("import", "csv", tmp_path / "tanks.csv", "--inputs", "u=uEst", "--outputs", "y=yEst",
                 "--test-columns", "u=uVal,y=yVal", "--units", "u=V,y=m", "--Ts", 4, "-o", tmp_path / "d")
    assert run.returncode == 0, run.stderr
    ds = load_dataset(tmp_path / "d")
    assert ds.Ts == 4.0 and ds.input_names == ["u"] and ds.outputs[0].unit == "m"
    np.testing.assert_array_equal(ds.train.u[0][:, 0], cols["uEst"])
    np.testing.assert_array_equal(ds.train.y[0][:, 0], cols["yEst"])
    np.testing.assert_array_equal(ds.test.u[0][:, 0], cols["uVal"])
    np.testing.assert_array_equal(ds.test.y[0][:, 0], cols["yVal"])
    assert ds.source["columns"] == {"train": ["uEst", "yEst"], "test": ["uVal", "yVal"]}


def test_cli_refuses_training_columns_only_and_writes_nothing(tmp_path):
    _tanks_csv(tmp_path / "tanks.csv")
    run = _nnfmu("import", "csv", tmp_path / "tanks.csv", "--inputs", "uEst", "--outputs", "yEst", "--Ts", 4,
                 "-o", tmp_path / "d")
    assert run.returncode == 2 and run.stderr.count("\n") == 1
    assert NO_TEST in run.stderr and "--test-columns" in run.stderr and "--test FILE" in run.stderr
    assert not (tmp_path / "d").exists()
    late = _nnfmu("import", "csv", tmp_path / "tanks.csv", "--inputs", "uEst", "--outputs", "yEst", "--Ts", 4,
                  "--test", tmp_path / "missing.csv", "-o", tmp_path / "d")  # fails after train was read
    assert late.returncode == 2 and "missing.csv not found" in late.stderr and not (tmp_path / "d").exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["tanks.csv"]


def test_load_csv_never_scores_on_the_training_data(tmp_path):
    _tanks_csv(tmp_path / "tanks.csv")
    f = tmp_path / "tanks.csv"
    with pytest.raises(DataError, match="test split would read the same columns of .*tanks.csv as the train split"):
        load_csv({"train": f, "test": f}, inputs=["uEst"], outputs=["yEst"], Ts=4.0)
    with pytest.raises(DataError, match=NO_TEST):
        load_csv(f, inputs=["uEst"], outputs=["yEst"], Ts=4.0)
    ds = load_csv(f, inputs={"u": "uEst"}, outputs={"y": "yEst"}, Ts=4.0, columns={"test": {"u": "uVal"}})
    assert ds.test.u[0][0, 0] != ds.train.u[0][0, 0]  # only the input remapped: y still reads yEst
    np.testing.assert_array_equal(ds.test.y[0], ds.train.y[0])
    by_index = load_csv(f, inputs=[0], outputs=[2], Ts=4.0, columns={"test": [1, 3]})
    assert by_index.input_names == ["uEst"] and by_index.output_names == ["yEst"]


def test_mat_matrices_per_split_files_time_column_and_valid_trajectories(tmp_path):
    rng = np.random.default_rng(1)
    t = np.arange(50) * 0.1
    for i in range(4):  # (2, N): channel-major like the robot benchmark, time along the longer axis
        scipy.io.savemat(tmp_path / f"run{i}.mat", {"t": t, "tau": rng.normal(size=(2, 50)),
                                                    "q": rng.normal(size=(50, 2)), "label": "a string"})
    files = {"train": [tmp_path / f"run{i}.mat" for i in range(3)], "test": tmp_path / "run3.mat"}
    ds = load_files(files, inputs={"tau": "tau"}, outputs=["q"], time_column="t", valid_trajectories=1, seed=0)
    assert ds.Ts == pytest.approx(0.1) and ds.input_names == ["tau1", "tau2"] and ds.output_names == ["q1", "q2"]
    assert (ds.train.n_traj, ds.valid.n_traj, ds.test.n_traj) == (2, 1, 1)
    raw = scipy.io.loadmat(tmp_path / "run3.mat")
    np.testing.assert_array_equal(ds.test.u[0], raw["tau"].T)
    one = load_files(files, inputs=["tau[1]"], outputs=["q[0]"], Ts=0.1)
    np.testing.assert_array_equal(one.test.u[0][:, 0], raw["tau"][1])
    with pytest.raises(DataError, match=r"has no column 'torque'; its columns are: tau, q, t"):
        load_files(files, inputs=["torque"], outputs=["q"], Ts=0.1)


def test_npz_and_headerless_csv(tmp_path):
    rng = np.random.default_rng(2)
    np.savez(tmp_path / "a.npz", u=rng.normal(size=40), y=rng.normal(size=(40, 1)))
    np.savez(tmp_path / "b.npz", u=rng.normal(size=30), y=rng.normal(size=(30, 1)))
    ds = load_files({"train": tmp_path / "a.npz", "test": tmp_path / "b.npz"}, inputs=["u"], outputs=["y"], Ts=1e-3)
    assert ds.train.lengths.tolist() == [40] and ds.test.lengths.tolist() == [30]
    np.savetxt(tmp_path / "plain.txt", rng.normal(size=(20, 3)))  # white space, no header
    np.savetxt(tmp_path / "plain_test.txt", rng.normal(size=(20, 3)))
    ds = load_files({"train": tmp_path / "plain.txt", "test": tmp_path / "plain_test.txt"}, inputs=[0, 1],
                    outputs=[2], Ts=1.0, units=["V", "V", "rad"])
    assert ds.input_names == ["u1", "u2"] and ds.output_names == ["y1"] and ds.outputs[0].unit == "rad"


def test_resampling_filters_what_the_new_sample_time_cannot_hold():
    Ts, q = 1e-3, 10
    t = np.arange(5000) * Ts
    slow = 2.0 + np.sin(2 * np.pi * 2.0 * t)      # 2 Hz, far below the new Nyquist frequency (50 Hz)
    fast = np.sin(2 * np.pi * 480.0 * t)           # 480 Hz: plain subsampling would alias it to 20 Hz
    out = decimate(np.column_stack([slow, slow + fast]), q)
    assert out.shape == (500, 2)
    np.testing.assert_allclose(out[:, 0], slow[::q], atol=1e-3)         # kept, without delay, up to both ends
    assert np.abs(out[:, 1] - slow[::q]).max() < 0.02                    # the 480 Hz part is gone
    assert np.abs((slow + fast)[::q] - slow[::q]).max() > 0.5            # naive subsampling keeps it
    with pytest.raises(DataError, match="too short to resample by 10"):
        decimate(np.zeros((20, 1)), q)


def test_import_resamples_and_records_it(tmp_path):
    rng = np.random.default_rng(3)
    for name in ("a", "b"):
        np.savez(tmp_path / f"{name}.npz", u=rng.normal(size=1000), y=rng.normal(size=1000))
    ds = load_files({"train": tmp_path / "a.npz", "test": tmp_path / "b.npz"}, inputs=["u"], outputs=["y"],
                    Ts=1e-3, resample=20)
    assert ds.Ts == pytest.approx(0.02) and ds.train.lengths.tolist() == [50]
    assert ds.source["resampled"]["factor"] == 20 and ds.source["resampled"]["original_Ts"] == 1e-3


def test_from_arrays_reads_nested_lists_as_one_trajectory():
    u = [[0.1], [0.2], [0.3], [0.5]]
    y = [[1.0], [1.5], [1.2], [0.9]]
    ds = from_arrays(Ts=0.1, u_train=u, y_train=y, u_test=u, y_test=y)
    assert ds.train.n_traj == 1 and ds.train.u[0].shape == (4, 1)
    ragged = from_arrays(Ts=0.1, u_train=[np.zeros((4, 1)), np.ones((3, 1))], y_train=[np.zeros((4, 1)),
                         np.ones((3, 1))], u_test=u, y_test=y)
    assert ragged.train.lengths.tolist() == [4, 3]


def test_save_dataset_refuses_a_dataset_without_test(tmp_path):
    u = np.random.default_rng(4).normal(size=(10, 1))
    ds = from_arrays(Ts=1.0, u_train=u, y_train=u, u_test=u, y_test=u)
    with pytest.raises(DataError, match="no 'test' split .* add held-out test data"):
        save_dataset(ds.replace(splits={"train": ds.train}), tmp_path / "d")
    assert not (tmp_path / "d").exists()
