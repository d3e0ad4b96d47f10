"""The dataset container and its folder format (docs/design.md, "Dataset on disk")."""

import json

import numpy as np
import pytest

import nnfmu
from nnfmu.data import Channel, Dataset, from_arrays, load_dataset, save_dataset
from nnfmu.errors import DataError, DataFileError, ShapeError


def _ragged(seed=0):
    rng = np.random.default_rng(seed)
    lens = [30, 17, 25]
    u = [rng.normal(size=(n, 2)) for n in lens]
    y = [rng.normal(loc=5.0, size=(n, 1)) for n in lens]
    return from_arrays(Ts=0.01, u_train=u, y_train=y, u_test=u[:1], y_test=y[:1],
                       input_names=[Channel("v", "V"), {"name": "i", "unit": "A"}],
                       output_names=[Channel("w", "rad/s")], source={"kind": "test", "seed": seed})


def test_round_trip_keeps_ragged_trajectories_exactly(tmp_path):
    ds = _ragged()
    save_dataset(ds, tmp_path / "d")
    back = load_dataset(tmp_path / "d")
    assert back.Ts == 0.01 and back.input_names == ["v", "i"] and back.outputs[0].unit == "rad/s"
    assert back.source == {"kind": "test", "seed": 0}
    assert back.train.lengths.tolist() == [30, 17, 25]
    for a, b in zip(ds.train.u + ds.train.y, back.train.u + back.train.y):
        np.testing.assert_array_equal(a, b)
    meta = json.loads((tmp_path / "d" / "meta.json").read_text())
    assert meta["inputs"] == [{"name": "v", "unit": "V"}, {"name": "i", "unit": "A"}]
    with np.load(tmp_path / "d" / "train.npz") as z:
        assert z["u"].shape == (3, 30, 2) and z["y"].shape == (3, 30, 1)


def test_padding_never_reaches_statistics(tmp_path):
    ds = _ragged()
    save_dataset(ds, tmp_path / "d")
    stats = load_dataset(tmp_path / "d").norm_stats()
    all_y = np.concatenate(ds.train.y)
    np.testing.assert_allclose(stats.y_mean, all_y.mean(0), rtol=1e-14)
    np.testing.assert_allclose(stats.y_std, all_y.std(0), rtol=1e-14)
    assert np.isfinite(stats.u_mean).all() and np.isfinite(stats.u_std).all()


def test_existing_folder_is_kept_unless_overwrite(tmp_path):
    ds = _ragged()
    save_dataset(ds, tmp_path / "d")
    with pytest.raises(DataFileError, match="already exists.*overwrite=True"):
        save_dataset(_ragged(1), tmp_path / "d")
    assert load_dataset(tmp_path / "d").source["seed"] == 0
    save_dataset(_ragged(1), tmp_path / "d", overwrite=True)
    assert load_dataset(tmp_path / "d").source["seed"] == 1
    assert sorted(p.name for p in tmp_path.iterdir()) == ["d"]


def test_failed_save_leaves_nothing(tmp_path, monkeypatch):
    import nnfmu.data.storage as storage

    def broken(file, tr):
        raise OSError("disk full")

    monkeypatch.setattr(storage, "_write_split", broken)
    with pytest.raises(DataFileError, match="disk full"):
        save_dataset(_ragged(), tmp_path / "d")
    assert list(tmp_path.iterdir()) == []


def test_unwritable_location(tmp_path):
    (tmp_path / "file").write_text("x")
    with pytest.raises(DataFileError, match="cannot write"):
        save_dataset(_ragged(), tmp_path / "file" / "d")


def test_nan_in_file_names_file_array_and_position(tmp_path):
    save_dataset(_ragged(), tmp_path / "d")
    with np.load(tmp_path / "d" / "train.npz") as z:
        arrays = dict(z)
    arrays["y"][1, 3, 0] = np.nan
    np.savez(tmp_path / "d" / "train.npz", **arrays)
    with pytest.raises(DataError, match=r"train\.npz: train trajectory 1: array 'y' .*non-finite.*step 3, channel 0, 0-based"):
        load_dataset(tmp_path / "d")


def test_mismatched_shapes_in_file(tmp_path):
    save_dataset(_ragged(), tmp_path / "d")
    np.savez(tmp_path / "d" / "test.npz", u=np.zeros((1, 10, 3)), y=np.zeros((1, 10, 1)))
    with pytest.raises(ShapeError, match=r"test\.npz: array 'u' has shape \(1, 10, 3\), expected \(n_traj, n_steps, 2\)"):
        load_dataset(tmp_path / "d")


@pytest.mark.parametrize("damage, match", [
    (lambda d: (d / "meta.json").unlink(), "meta.json not found"),
    (lambda d: (d / "meta.json").write_text("{nope"), "not valid JSON"),
    (lambda d: (d / "train.npz").write_bytes(b"garbage"), r"train\.npz cannot be read"),
])
def test_broken_folder_errors(tmp_path, damage, match):
    save_dataset(_ragged(), tmp_path / "d")
    damage(tmp_path / "d")
    with pytest.raises(DataFileError, match=match):
        load_dataset(tmp_path / "d")


def test_missing_folder():
    with pytest.raises(DataFileError, match="not found.*nnfmu generate"):
        load_dataset("/nonexistent/dataset")


def test_missing_split_is_named():
    ds = _ragged()
    assert ds.valid is None
    with pytest.raises(DataError, match="no 'valid' split"):
        ds.split("valid")


def test_from_arrays_errors():
    with pytest.raises(ShapeError, match="u has 10 samples but y has 9"):
        from_arrays(Ts=1.0, u_train=np.zeros((10, 1)), y_train=np.zeros((9, 1)),
                    u_test=np.zeros((10, 1)), y_test=np.zeros((10, 1)))
    with pytest.raises(DataError, match="Ts must be a positive"):
        from_arrays(Ts=0.0, u_train=np.zeros((10, 1)), y_train=np.zeros((10, 1)),
                    u_test=np.zeros((10, 1)), y_test=np.zeros((10, 1)))
    with pytest.raises(DataError, match="not an identifier"):
        Channel("bad name")
    with pytest.raises(DataError, match="unique"):
        from_arrays(Ts=1.0, u_train=np.zeros((10, 1)), y_train=np.zeros((10, 1)),
                    u_test=np.zeros((10, 1)), y_test=np.zeros((10, 1)), input_names=["a"], output_names=["a"])


def test_with_validation_many_and_single_trajectories():
    rng = np.random.default_rng(1)
    ds = from_arrays(Ts=1.0, u_train=rng.normal(size=(20, 8, 1)), y_train=rng.normal(size=(20, 8, 1)),
                     u_test=rng.normal(size=(8, 1)), y_test=rng.normal(size=(8, 1)))
    split = ds.with_validation(0.2, seed=3)
    assert split.train.n_traj == 16 and split.valid.n_traj == 4
    seen = {a.tobytes() for a in split.train.u} | {a.tobytes() for a in split.valid.u}
    assert seen == {a.tobytes() for a in ds.train.u}  # a partition, nothing lost or duplicated
    one = from_arrays(Ts=1.0, u_train=rng.normal(size=(100, 1)), y_train=rng.normal(size=(100, 1)),
                      u_test=rng.normal(size=(8, 1)), y_test=rng.normal(size=(8, 1))).with_validation(0.2)
    assert one.train.lengths.tolist() == [80] and one.valid.lengths.tolist() == [20]


def test_measurement_noise_is_seeded_scaled_per_output_and_recorded():
    rng = np.random.default_rng(2)
    y = rng.normal(size=(40, 500, 2)) * np.array([1e-3, 2e5])  # outputs of very different scales
    ds = from_arrays(Ts=1.0, u_train=rng.normal(size=(40, 500, 1)), y_train=y,
                     u_test=rng.normal(size=(3, 200, 1)), y_test=rng.normal(size=(3, 200, 2)))
    noisy = ds.with_measurement_noise(0.05, seed=7)
    assert noisy.with_measurement_noise(0.0).train.y[0].tobytes() == noisy.train.y[0].tobytes()
    again = ds.with_measurement_noise(0.05, seed=7)
    assert all(np.array_equal(a, b) for a, b in zip(noisy.test.y, again.test.y))
    assert all(np.array_equal(a, b) for a, b in zip(noisy.train.u, ds.train.u))  # inputs stay exact
    noise = np.concatenate(noisy.train.y) - np.concatenate(ds.train.y)
    ratio = noise.std(axis=0) / (0.05 * np.concatenate(ds.train.y).std(axis=0))
    np.testing.assert_allclose(ratio, 1.0, atol=0.02)
    assert noisy.source["measurement_noise"]["fraction_of_train_std"] == 0.05
    with pytest.raises(DataError, match=r"measurement noise must be a fraction .* in \[0, 1\)"):
        ds.with_measurement_noise(5.0)


def test_windows_never_straddle_trajectories():
    ds = _ragged()
    w = ds.train.windows(10, stride=5)
    # lengths 30, 17, 25 -> starts 0..20 (5), 0..5 (2), 0..15 (4)
    assert w.n_traj == 11 and set(w.lengths.tolist()) == {10}
    np.testing.assert_array_equal(w.u[5], ds.train.u[1][0:10])
    with pytest.raises(ShapeError, match="choose a shorter window"):
        ds.train.windows(100)


def test_public_api_reexported():
    assert nnfmu.Dataset is Dataset and nnfmu.load_dataset is load_dataset
    assert "nrmse" in dir(nnfmu)
    for name in nnfmu.__all__:  # every advertised name resolves, so the lazy table has no typo
        assert getattr(nnfmu, name) is not None, name
