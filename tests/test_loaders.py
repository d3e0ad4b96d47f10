"""Loaders for external formats, tested on small files written here in the documented layouts."""

import subprocess
import sys

import h5py
import numpy as np
import pytest
import scipy.io

from nnfmu.data import load_csv, load_dataset, load_robot_benchmark
from nnfmu.errors import DataError, DataFileError, ShapeError


def _official_arrays(n_train=50, n_test=20, seed=0):
    rng = np.random.default_rng(seed)
    Ts = 0.100002500812
    return {
        "time_train": (np.arange(n_train) * Ts)[None, :],
        "time_test": (np.arange(n_test) * Ts)[None, :],
        "u_train": rng.normal(size=(6, n_train)), "y_train": rng.normal(size=(6, n_train)) * 50,
        "u_test": rng.normal(size=(6, n_test)), "y_test": rng.normal(size=(6, n_test)) * 50,
    }


def test_official_layout_v5(tmp_path):
    arr = _official_arrays()
    scipy.io.savemat(tmp_path / "robot.mat", arr)
    ds = load_robot_benchmark(tmp_path / "robot.mat")
    assert ds.Ts == pytest.approx(0.100002500812, rel=1e-12)
    assert ds.input_names == [f"tau{j}" for j in range(1, 7)] and ds.outputs[0].unit == "deg"
    assert ds.train.n_traj == 1 and ds.test.n_traj == 1 and ds.valid is None
    # channel-major (6, N) on disk -> (N, 6) in nnfmu, channel j stays channel j
    np.testing.assert_array_equal(ds.train.u[0], arr["u_train"].T)
    np.testing.assert_array_equal(ds.test.y[0], arr["y_test"].T)
    assert ds.source["layout"] == "official"


def test_official_layout_v73_hdf5(tmp_path):
    arr = _official_arrays()
    path = tmp_path / "robot73.mat"
    with h5py.File(path, "w", userblock_size=512) as f:
        for k, v in arr.items():
            f[k] = v.T  # MATLAB v7.3 stores column-major, so h5py sees the transpose
    with open(path, "r+b") as f:
        text = b"MATLAB 7.3 MAT-file, Platform: GLNXA64, Created on: test HDF5 schema 1.00 ."
        f.write(text.ljust(116) + bytes(8) + b"\x00\x02IM")  # the 128-byte MATLAB v7.3 header
    ds = load_robot_benchmark(path)
    np.testing.assert_array_equal(ds.train.y[0], arr["y_train"].T)


def test_recut_layout_pieces_and_padding(tmp_path):
    rng = np.random.default_rng(1)
    piece = 605
    arr = {f"{v}_{s}": rng.normal(size=(6, n * piece)) for v in "uy" for s, n in (("train", 3), ("val", 2), ("test", 2))}
    arr["u_val"][:, -8:] = 0.0                      # zero torque padding at the end, as in the shared file
    arr["y_val"][:, -9:] = arr["y_val"][:, [-10]]   # held output beside it
    scipy.io.savemat(tmp_path / "recut.mat", arr)
    ds = load_robot_benchmark(tmp_path / "recut.mat")
    assert ds.train.lengths.tolist() == [605] * 3
    assert ds.valid.lengths.tolist() == [605, 605 - 9]
    assert ds.test.n_traj == 1 and ds.test.lengths.tolist() == [1210]  # scored as one record
    np.testing.assert_array_equal(ds.train.u[1], arr["u_train"][:, 605:1210].T)
    assert "NOT the original" in ds.source["caveat"]


def test_robot_errors(tmp_path):
    with pytest.raises(DataFileError, match="not found"):
        load_robot_benchmark(tmp_path / "missing.mat")
    (tmp_path / "junk.mat").write_bytes(b"\x00" * 300)
    with pytest.raises(DataFileError, match="not a readable MATLAB"):
        load_robot_benchmark(tmp_path / "junk.mat")
    scipy.io.savemat(tmp_path / "partial.mat", {"u_train": np.zeros((6, 5))})
    with pytest.raises(DataFileError, match=r"lacks \['u_test', 'y_test', 'y_train'\]"):
        load_robot_benchmark(tmp_path / "partial.mat")
    arr = _official_arrays()
    arr["y_test"] = arr["y_test"][:, :-1]
    scipy.io.savemat(tmp_path / "short.mat", arr)
    with pytest.raises(ShapeError, match="u_test has 20 samples but y_test has 19"):
        load_robot_benchmark(tmp_path / "short.mat")


def test_import_cli_writes_dataset_folder(tmp_path):
    scipy.io.savemat(tmp_path / "robot.mat", _official_arrays())
    out = tmp_path / "ds"
    run = subprocess.run([sys.executable, "-m", "nnfmu", "import", "robot-benchmark", str(tmp_path / "robot.mat"),
                          "--out", str(out)], capture_output=True, text=True)
    assert run.returncode == 0, run.stderr
    ds = load_dataset(out)
    assert ds.train.lengths.tolist() == [50] and ds.test.lengths.tolist() == [20]
    again = subprocess.run([sys.executable, "-m", "nnfmu", "import", "robot-benchmark", str(tmp_path / "robot.mat"),
                            "--out", str(out)], capture_output=True, text=True)
    assert again.returncode == 2 and again.stderr.count("\n") == 1 and "--force" in again.stderr


def test_csv_loader(tmp_path):
    t = np.arange(20) * 0.5
    for name, offset in (("a.csv", 0.0), ("b.csv", 1.0), ("c.csv", 2.0)):
        rows = ["time,volt,speed"] + [f"{ti},{np.sin(ti) + offset},{np.cos(ti)}" for ti in t]
        (tmp_path / name).write_text("\n".join(rows) + "\n")
    ds = load_csv({"train": [tmp_path / "a.csv", tmp_path / "b.csv"], "test": tmp_path / "c.csv"},
                  inputs=["volt"], outputs=["speed"], time_column="time", units={"volt": "V"})
    assert ds.Ts == 0.5 and ds.train.n_traj == 2 and ds.inputs[0].unit == "V"
    np.testing.assert_allclose(ds.test.u[0][:, 0], np.sin(t) + 2.0)
    with pytest.raises(DataError, match=r"has no column 'torque'; its columns are: time, volt, speed"):
        load_csv({"train": tmp_path / "a.csv", "test": tmp_path / "c.csv"}, inputs=["torque"], outputs=["speed"],
                 Ts=0.5)
    named = load_csv({"train": tmp_path / "a.csv", "test": tmp_path / "c.csv"}, inputs=["volt"], outputs=["speed"])
    assert named.Ts == 0.5 and "used the column 'time'" in named.source["notes"][0]  # no timing given: by its name
    with pytest.raises(DataError, match="give the sample time one way"):
        load_csv({"train": tmp_path / "a.csv", "test": tmp_path / "c.csv"}, inputs=["volt"], outputs=["speed"],
                 Ts=0.5, time_column="time")
