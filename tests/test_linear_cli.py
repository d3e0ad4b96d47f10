"""``nnfmu linear``: identify, save the matrices, build the FMU, and fmpy agrees with the model."""

from __future__ import annotations

import numpy as np
import pytest

from nnfmu.cli import main
from nnfmu.data import Channel, from_arrays, save_dataset
from nnfmu.linear import load_linear


def _system_data(seed: int = 0):
    """A third-order two-input, two-output system from rest, with a little output noise."""
    rng = np.random.default_rng(seed)
    A = np.array([[0.9, 0.2, 0.0], [-0.2, 0.9, 0.1], [0.0, 0.0, 0.7]])
    B, C = rng.normal(size=(3, 2)), rng.normal(size=(2, 3)) * [[100.0], [0.01]]

    def run(u):
        x, y = np.linalg.solve(np.eye(3) - A, B @ u[0]), np.empty((len(u), 2))
        for k, uk in enumerate(u):
            y[k], x = C @ x + [20.0, 0.0], A @ x + B @ uk
        return y + rng.normal(size=y.shape) * [0.5, 5e-5]

    us = [rng.normal(size=(n, 2)) + [0.0, 4.0] for n in (80, 120, 100, 150, 200)]
    ys = [run(u) for u in us]
    return from_arrays(Ts=0.05, u_train=us[:3], y_train=ys[:3], u_valid=us[3:4], y_valid=ys[3:4],
                       u_test=us[4:], y_test=ys[4:], input_names=[Channel("torque", "N.m"), Channel("volt", "V")],
                       output_names=[Channel("angle", "deg"), Channel("gap", "m")])


@pytest.fixture(scope="module")
def data_dir(tmp_path_factory):
    return save_dataset(_system_data(), tmp_path_factory.mktemp("linear") / "data")


def test_save_writes_a_model_that_scores_as_printed(data_dir, tmp_path, capsys):
    assert main(["linear", "--data", str(data_dir), "--order", "3", "--save", str(tmp_path / "m.json")]) == 0
    out = capsys.readouterr().out
    assert "order 3 (forced)" in out and "free-run NRMSE on valid" in out
    model = load_linear(tmp_path / "m.json")
    assert model.n_x == 3 and [c.name for c in model.outputs] == ["angle", "gap"]
    test = _system_data().test
    from nnfmu.metrics import nrmse

    score = nrmse(test.y[0], model.simulate(test.u[0], test.y[0][0])).mean
    assert f"free-run NRMSE on test: {score:.4f}" in out
    assert score < 0.05  # the noise is small, so a third-order model fits well


@pytest.mark.parametrize("fmi_version,init", [(2, "estimate"), (3, "zero-offset")])
def test_fmu_simulates_like_the_model(data_dir, tmp_path, capsys, fmi_version, init):
    from nnfmu.cosim import simulate_split
    from nnfmu.data import load_dataset

    fmu, saved = tmp_path / "linear.fmu", tmp_path / "linear.json"
    argv = ["linear", "--data", str(data_dir), "--init", init, "--max-evaluations", "20",
            "-o", str(fmu), "--save", str(saved), "--fmi-version", str(fmi_version)]
    assert main(argv) == 0
    assert f"FMI {fmi_version}.0" in capsys.readouterr().out
    model, ds = load_linear(saved), load_dataset(data_dir)
    (got,) = simulate_split(fmu, ds, "test")
    want = model.simulate(ds.test.u[0], ds.test.y[0][0])
    scale = np.abs(want).max(axis=0)  # the outputs differ by 1e4 in size: compare each on its own scale
    np.testing.assert_allclose(got / scale, want / scale, rtol=0, atol=1e-9)


def test_nothing_to_write_is_an_error(data_dir, capsys):
    assert main(["linear", "--data", str(data_dir)]) == 2
    assert "nothing to write; give -o MODEL.fmu" in capsys.readouterr().err


def test_missing_dataset_and_bad_order(tmp_path, data_dir, capsys):
    assert main(["linear", "--data", str(tmp_path / "nope"), "--save", str(tmp_path / "m.json")]) == 2
    assert "not found" in capsys.readouterr().err
    assert main(["linear", "--data", str(data_dir), "--order", "0", "--save", str(tmp_path / "m.json")]) == 2
    assert "--order must be a whole number >= 1" in capsys.readouterr().err
    assert not (tmp_path / "m.json").exists()


def test_one_record_holds_out_the_tail_train_holds_out_so_networks_start_from_this_model(tmp_path, capsys):
    """On one record without a valid split, `nnfmu linear` is the model `nnfmu train` puts its networks on."""
    from nnfmu.cli._train_plan import prepare
    from nnfmu.data import load_dataset
    from nnfmu.models import ModelConfig
    from nnfmu.training import TrainConfig
    from nnfmu.training.plan import valid_fraction

    ds = _system_data()
    one = from_arrays(Ts=ds.Ts, u_train=[np.concatenate(ds.train.u)], y_train=[np.concatenate(ds.train.y)],
                      u_test=list(ds.test.u), y_test=list(ds.test.y))
    data = save_dataset(one, tmp_path / "one")
    assert main(["linear", "--data", str(data), "--save", str(tmp_path / "held.json"), "--quiet"]) == 0
    out = capsys.readouterr().out
    assert f"the last {valid_fraction(one):.0%} of the record" in out and "free-run NRMSE on valid" in out
    held = load_linear(tmp_path / "held.json")

    loaded = load_dataset(data)
    _, _, _, start = prepare(loaded, ModelConfig(arch="gru", n_u=2, n_y=2), TrainConfig(), {})  # --arch gru
    for name in ("A", "B", "C", "d"):
        np.testing.assert_array_equal(getattr(held.system, name), getattr(start.system, name))

    assert main(["linear", "--data", str(data), "--valid-fraction", "0", "--save", str(tmp_path / "all.json"),
                 "--quiet"]) == 0
    assert "free-run NRMSE on train" in capsys.readouterr().out  # the whole record, the order chosen on it
    assert main(["linear", "--data", str(data), "--valid-fraction", "1.5", "-o", str(tmp_path / "x.fmu")]) == 2
    assert "--valid-fraction" in capsys.readouterr().err and not (tmp_path / "x.fmu").exists()


def test_one_record_is_refitted_whole_after_the_order_is_chosen_on_its_tail(tmp_path, capsys):
    """The tail chooses the order and the refinement's length; the model is then fitted on the whole record."""
    ds = _system_data()
    record = [np.concatenate(ds.train.u + ds.valid.u)], [np.concatenate(ds.train.y + ds.valid.y)]
    one = from_arrays(Ts=ds.Ts, u_train=record[0], y_train=record[1], u_test=list(ds.test.u), y_test=list(ds.test.y))
    data = save_dataset(one, tmp_path / "one")
    assert main(["linear", "--data", str(data), "--save", str(tmp_path / "refit.json"), "--quiet"]) == 0
    out = capsys.readouterr().out
    n = len(record[0][0])
    assert f"refit on the training and validation data together ({n} samples in 1 record, order" in out
    assert main(["linear", "--data", str(data), "--no-refit", "--save", str(tmp_path / "held.json"), "--quiet"]) == 0
    assert "refit on" not in capsys.readouterr().out
    refit, held = load_linear(tmp_path / "refit.json"), load_linear(tmp_path / "held.json")
    assert refit.n_x == held.n_x  # the order chosen on the tail is kept
    assert refit.info["refit"]["samples"] == n and "refit" not in held.info
    assert not np.allclose(refit.system.A, held.system.A)  # estimated again, on 100 % instead of 75 %
    assert refit.info["refit"]["nrmse_valid_before"] == pytest.approx(held.info["nrmse_valid"], rel=1e-12)


def _pieces_of_one_recording(contiguous: bool = True):
    """The third-order system run once for 1000 samples and cut into consecutive pieces of 100 (the robot
    benchmark's layout, smaller): 6 for training, 2 for validation, the last 200 for the test."""
    rng = np.random.default_rng(3)
    A = np.array([[0.95, 0.2, 0.0], [-0.2, 0.95, 0.1], [0.0, 0.0, 0.8]])
    B, C = rng.normal(size=(3, 1)), rng.normal(size=(1, 3))
    u, x, y = rng.normal(size=(1000, 1)), np.zeros(3), np.empty((1000, 1))
    for k in range(1000):
        y[k], x = C @ x, A @ x + B @ u[k]
    y += rng.normal(size=y.shape) * 0.01
    cut = lambda a, lo, hi: [a[i:i + 100] for i in range(lo, hi, 100)]  # noqa: E731
    return from_arrays(Ts=0.1, u_train=cut(u, 0, 600), y_train=cut(y, 0, 600), u_valid=cut(u, 600, 800),
                       y_valid=cut(y, 600, 800), u_test=[u[800:]], y_test=[y[800:]],
                       source={"contiguous": contiguous})


def test_consecutive_pieces_of_one_recording_are_identified_joined_as_train_joins_them(tmp_path, capsys):
    """Pieces the dataset calls consecutive are fitted as the one recording they are (the networks' training
    joins them too), not each from its own start: the model is the joined records' model; --no-join is not."""
    data = save_dataset(_pieces_of_one_recording(), tmp_path / "pieces")
    assert main(["linear", "--data", str(data), "--order", "3", "--save", str(tmp_path / "j.json"), "--quiet"]) == 0
    assert "the 6 training and 2 validation records joined end to end" in capsys.readouterr().out
    joined = _pieces_of_one_recording(contiguous=False)
    one = joined.replace(splits={**joined.splits, "train": joined.train.concatenated(),
                                 "valid": joined.valid.concatenated()})
    assert main(["linear", "--data", str(save_dataset(one, tmp_path / "one")), "--order", "3",
                 "--save", str(tmp_path / "one.json"), "--quiet"]) == 0
    assert main(["linear", "--data", str(data), "--order", "3", "--no-join", "--save", str(tmp_path / "apart.json"),
                 "--quiet"]) == 0
    assert "joined end to end" not in capsys.readouterr().out
    model, reference, apart = (load_linear(tmp_path / f"{n}.json") for n in ("j", "one", "apart"))
    assert model.info["joined"] == {"train": 6, "valid": 2} and apart.info["joined"] is None
    for name in ("A", "B", "C"):
        np.testing.assert_allclose(getattr(model.system, name), getattr(reference.system, name), rtol=0, atol=1e-12)
    assert not np.allclose(model.system.A, apart.system.A)
    assert model.info["refit"]["records"] == 2  # the joined training and validation records
