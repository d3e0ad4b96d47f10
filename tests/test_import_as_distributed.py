"""Benchmark files imported as they come: trailing commas, a sample rate given once, sample times that agree to a
tolerance, 0-based positions in every message, and the refusals of files with no data (issues 21 and 24)."""

import json

import numpy as np
import pytest

from nnfmu.cli import main
from nnfmu.data import load_dataset, load_files
from nnfmu.errors import DataError


def _f16_like(path, n=64, seed=0, fs=400):
    """A CSV in the F-16 benchmark's layout: quoted header and every line ending in a comma, Fs in row 0 only."""
    rng = np.random.default_rng(seed)
    lines = ['"Force","Voltage","Acceleration1","Acceleration2","Acceleration3","Fs",']
    for i in range(n):
        row = [f"{v:.6g}" for v in rng.normal(size=5)] + [str(fs) if i == 0 else ""]
        lines.append(",".join(row) + ",")
    path.write_text("\n".join(lines) + "\n")
    return np.loadtxt(path, delimiter=",", skiprows=1, usecols=range(5))


def _one_error_line(capsys) -> str:
    err = capsys.readouterr().err
    assert "Traceback" not in err and err.count("\n") == 1, err
    return err


def test_f16_layout_imports_as_distributed(tmp_path, capsys):
    train = _f16_like(tmp_path / "F16Data_FullMSine_Level5.csv")
    test = _f16_like(tmp_path / "F16Data_FullMSine_Level6_Validation.csv", seed=1)
    out = tmp_path / "f16"
    assert main(["import", "csv", str(tmp_path / "F16Data_FullMSine_Level5.csv"), "--inputs", "Force",
                 "--outputs", "Acceleration1", "Acceleration2", "Acceleration3", "--fs-column", "Fs",
                 "--test", str(tmp_path / "F16Data_FullMSine_Level6_Validation.csv"), "-o", str(out)]) == 0
    ds = load_dataset(out)
    assert ds.Ts == 1 / 400 and ds.input_names == ["Force"]
    assert ds.output_names == ["Acceleration1", "Acceleration2", "Acceleration3"]
    np.testing.assert_array_equal(ds.train.u[0][:, 0], train[:, 0])
    np.testing.assert_array_equal(ds.test.y[0], test[:, 2:5])
    # the dataset is named after its folder, and so are the models trained on it (not after the first CSV)
    from nnfmu.training.trainer import dataset_meta

    assert ds.source["name"] == "f16" and dataset_meta(ds, "gru")["name"] == "f16_gru"


def test_a_picked_column_with_an_empty_field_names_its_0_based_row_and_column(tmp_path, capsys):
    _f16_like(tmp_path / "a.csv")
    with pytest.raises(DataError, match=r"row 1, column 5 \('Fs'\) is empty \(0-based positions.*--fs-column"):
        load_files({"train": tmp_path / "a.csv", "test": tmp_path / "a.csv"}, inputs=["Fs"], outputs=["Force"],
                   Ts=1.0, columns={"test": ["Voltage", "Acceleration1"]})
    (tmp_path / "b.csv").write_text("u,y,\n1,2,\n3,x,\n")
    assert main(["import", "csv", str(tmp_path / "b.csv"), "--inputs", "u", "--outputs", "1", "--Ts", "1",
                 "--test-columns", "1,0", "-o", str(tmp_path / "d")]) == 2
    assert "row 1, column 1 ('y') holds 'x', not a number (0-based" in _one_error_line(capsys)
    with pytest.raises(DataError, match=r"column index 2 is out of range; the file has 2 columns \(0 .. 1, 0-based"):
        load_files({"train": tmp_path / "b.csv", "test": tmp_path / "b.csv"}, inputs=[2], outputs=[0], Ts=1.0)


def test_sample_time_as_a_setting_column_or_a_single_number(tmp_path):
    (tmp_path / "a.csv").write_text("u,y,Ts\n" + "".join(f"{i},{2 * i},{'0.5' if i < 2 else ''}\n"
                                                        for i in range(10)))
    ds = load_files(tmp_path / "a.csv", inputs=["u"], outputs=["y"], Ts_column="Ts", columns={"test": ["y", "u"]})
    assert ds.Ts == 0.5
    np.savez(tmp_path / "b.npz", u=np.arange(10.0), y=np.arange(10.0) ** 2, fs=20.0)
    assert load_files({"train": tmp_path / "b.npz", "test": tmp_path / "b.npz"}, inputs=["u"], outputs=["y"],
                      fs_column="fs", columns={"test": ["y", "u"]}).Ts == 0.05
    (tmp_path / "c.csv").write_text("u,y,Ts\n1,2,0.5\n3,4,0.25\n5,6,\n")
    with pytest.raises(DataError, match=r"'Ts' should hold one value, but row 0 holds 0.5 and row 1 0.25"):
        load_files(tmp_path / "c.csv", inputs=["u"], outputs=["y"], Ts_column="Ts", columns={"test": ["y", "u"]})
    with pytest.raises(DataError, match="give the sample time one way.*got Ts and fs_column"):
        load_files(tmp_path / "b.npz", inputs=["u"], outputs=["y"], Ts=1.0, fs_column="fs", columns={"test": [0, 1]})


def _timed_csv(path, Ts, t0=1000.0, n=50, decimals=6):
    t = t0 + np.arange(n) * Ts
    path.write_text("t,u,y\n" + "".join(f"{ti:.{decimals}f},{np.sin(i)},{np.cos(i)}\n" for i, ti in enumerate(t)))


def test_sample_times_that_agree_to_1e_4_share_the_training_files_ts(tmp_path, capsys):
    _timed_csv(tmp_path / "x.csv", 0.001, decimals=9)
    _timed_csv(tmp_path / "z.csv", 0.001 * (1 + 2.4e-5), decimals=9)  # the two EMPS axis files differ so
    files = {"train": tmp_path / "x.csv", "test": tmp_path / "z.csv"}
    assert load_files(files, inputs=["u"], outputs=["y"], time_column="t").Ts == 0.001
    _timed_csv(tmp_path / "far.csv", 0.00101, decimals=9)
    assert main(["import", "csv", str(tmp_path / "x.csv"), "--inputs", "u", "--outputs", "y", "--time", "t",
                 "--test", str(tmp_path / "far.csv"), "-o", str(tmp_path / "d")]) == 2
    assert "differ by more than 0.0001 (relative)" in _one_error_line(capsys)
    assert load_files({"train": tmp_path / "x.csv", "test": tmp_path / "far.csv"}, inputs=["u"], outputs=["y"],
                      Ts=0.001).Ts == 0.001  # Ts forces one


def test_a_measured_sample_time_is_rounded_to_what_the_time_stamps_resolve(tmp_path):
    _timed_csv(tmp_path / "a.csv", 0.1, decimals=1)  # 1000.0, 1000.1, ...: the steps are 0.09999999999990905
    _timed_csv(tmp_path / "b.csv", 0.1, decimals=1, t0=0.0)
    assert main(["import", "csv", str(tmp_path / "a.csv"), "--inputs", "u", "--outputs", "y", "--time", "t",
                 "--test", str(tmp_path / "b.csv"), "-o", str(tmp_path / "d")]) == 0
    assert json.loads((tmp_path / "d" / "meta.json").read_text())["Ts"] == 0.1
    t = 5.0 + np.arange(30) / 3.0  # stamps at full precision: 1/3 s stays 1/3 s
    np.savez(tmp_path / "c.npz", t=t, u=np.sin(t), y=np.cos(t))
    Ts = load_files({"train": tmp_path / "c.npz", "test": tmp_path / "c.npz"}, inputs=["u"], outputs=["y"],
                    time_column="t", columns={"test": ["y", "u"]}).Ts
    assert Ts == pytest.approx(1 / 3, rel=1e-12) and Ts != round(Ts, 6)


@pytest.mark.parametrize("rows, timing, message", [
    ("", ["--Ts", "0.01"], "has a header row but no rows of data"),
    ("0,1,2\n", ["--time", "t"], "has 1 row(s); measuring the sample time needs at least 2"),
    ("0,1,2\n", ["--Ts", "0.01"], "has 1 row(s) of samples; a trajectory needs at least 2"),
])
def test_files_without_enough_rows_give_one_line_and_write_nothing(tmp_path, capsys, rows, timing, message):
    (tmp_path / "short.csv").write_text("t,u,y\n" + rows)
    (tmp_path / "test.csv").write_text("t,u,y\n0,1,2\n0.01,3,4\n0.02,5,6\n")
    assert main(["import", "csv", str(tmp_path / "short.csv"), "--inputs", "u", "--outputs", "y", *timing,
                 "--test", str(tmp_path / "test.csv"), "-o", str(tmp_path / "D")]) == 2
    assert message in _one_error_line(capsys)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["short.csv", "test.csv"]


def test_a_column_of_objects_or_text_is_not_numeric_rather_than_missing(tmp_path, capsys):
    np.savez(tmp_path / "o.npz", u=np.array([1, 2, 3], dtype=object), y=np.arange(3.0), label=np.array(["a", "b"]))
    for ref, what in (("u", "is an array of Python objects"), ("label", "holds text")):
        with pytest.raises(DataError, match=rf"'{ref}' {what}.*not a numeric signal; save it as a float"):
            load_files({"train": tmp_path / "o.npz", "test": tmp_path / "o.npz"}, inputs=[ref], outputs=["y"],
                       Ts=1.0, columns={"test": ["y", "y"]})


def test_a_measured_sample_time_of_float_noise_is_snapped_to_its_round_value_and_said(tmp_path, capsys):
    """Issue 37, item 9: the 1 kHz axis record's time vector gave Ts = 0.0009999839611 s, which a model's
    Ts = 0.001 refused."""
    import scipy.io

    t = 12.345678901 + np.arange(400) * 0.0009999839611
    for name in ("a.mat", "b.mat"):
        scipy.io.savemat(tmp_path / name, {"t": t[:, None], "u": np.sin(t)[:, None], "y": np.cos(t)[:, None]})
    assert main(["import", "mat", str(tmp_path / "a.mat"), "--time", "t", "--inputs", "u", "--outputs", "y",
                 "--test", str(tmp_path / "b.mat"), "-o", str(tmp_path / "d")]) == 0
    assert load_dataset(tmp_path / "d").Ts == 0.001
    assert "its median step 0.0009999839611 s is taken as 0.001 s" in capsys.readouterr().out


def test_a_column_named_ts_fs_or_time_gives_the_sample_time_when_none_is_given(tmp_path, capsys):
    """Issue 37, item 9: the two-tank CSV carries its sample time in a column named Ts."""
    for name, head, first in (("ts", "Ts", 4.0), ("fs", "fs", 0.25), ("time", "time", None)):
        rows = [f"{first if first is not None else 4.0 * k},{k % 3},{k % 5}" for k in range(20)]
        for f in ("a.csv", "b.csv"):
            (tmp_path / f).write_text(f"{head},u,y\n" + "\n".join(rows) + "\n")
        out = tmp_path / name
        assert main(["import", "csv", str(tmp_path / "a.csv"), "--inputs", "u", "--outputs", "y",
                     "--test", str(tmp_path / "b.csv"), "-o", str(out)]) == 0
        assert load_dataset(out).Ts == 4.0
        assert f"no sample time given: used the column {head!r} of a.csv" in capsys.readouterr().out


def test_a_models_sample_time_meets_the_datas_within_the_same_tolerance():
    import dataclasses

    from nnfmu.data import from_arrays
    from nnfmu.greybox.setup import check_dataset
    from nnfmu.physics import slider_system

    system = slider_system()
    u = [np.ones((20, 1))] * 2

    def data(Ts):
        return from_arrays(Ts=Ts, u_train=u, y_train=u, u_test=u, y_test=u, input_names=["F"],
                           output_names=["pos"]).with_units({"F": "N", "pos": "m"})

    check_dataset(system, data(system.Ts * (1 + 5e-5)))  # a measured 0.0099995 s is the model's 0.01 s
    with pytest.raises(DataError, match="sample time"):
        check_dataset(dataclasses.replace(system), data(system.Ts * (1 + 5e-4)))
