"""Checkpoints: weights_only-safe contents, round trip, and clear errors for bad files."""

from __future__ import annotations

import pickle

import numpy as np
import pytest
import torch

import nnfmu
from nnfmu.errors import CheckpointError, DataFileError
from nnfmu.models import ModelConfig, build_model, load_checkpoint, load_model, save_checkpoint
from builtin_networks import ARCHS

META = {"name": "valve_test", "Ts": 4e-5, "inputs": [{"name": "u1", "unit": "V"}, {"name": "u2", "unit": "V"}],
        "outputs": [{"name": "s", "unit": "m"}, {"name": "p", "unit": "Pa"}], "source": {"seed": 3}}


def trained_like(arch: str):
    torch.manual_seed(0)
    model = build_model(ModelConfig(arch=arch, n_u=2, n_y=2, hidden=5, layers=2), META)
    model.set_normalisation({"u_mean": [100, 120], "u_std": [70, 60], "y_mean": [5e-4, 4e5], "y_std": [3e-4, 1.5e5]})
    return model


@pytest.fixture
def saved(tmp_path):
    model = trained_like("lstm")
    path = save_checkpoint(tmp_path / "sub" / "m.pt", model, train_config={"strategy": "parallel"},
                           history=[{"epoch": 0, "valid_nrmse": 1.5}], best_epoch=0, summary={"test_nrmse": 0.3},
                           resume={"epoch": 0, "torch_rng": torch.get_rng_state()})
    return model, path


@pytest.mark.parametrize("arch", ARCHS)
def test_round_trip_keeps_weights_normalisation_and_meta(arch, tmp_path):
    model = trained_like(arch)
    path = save_checkpoint(tmp_path / f"{arch}.pt", model)
    raw = torch.load(path, weights_only=True)  # plain containers only: no unrestricted pickle needed
    assert raw["format"] == "nnfmu-checkpoint" and raw["model_config"]["arch"] == arch
    loaded = nnfmu.load_model(path)
    assert loaded.config == model.config and loaded.meta == META and not loaded.training
    for key, value in model.state_dict().items():
        assert torch.equal(loaded.state_dict()[key], value), key
    u = np.random.default_rng(0).uniform(0, 250, (50, 2))
    y0 = np.array([2e-4, 3e5])
    out = loaded.simulate(u, y0)
    np.testing.assert_array_equal(out, model.simulate(u, y0))
    assert out.shape == (50, 2) and np.isfinite(out).all() and np.array_equal(out[0], y0)


def test_checkpoint_holds_training_records_and_provenance(saved):
    _, path = saved
    ckpt = load_checkpoint(path)
    assert ckpt["history"] == [{"epoch": 0, "valid_nrmse": 1.5}] and ckpt["summary"]["test_nrmse"] == 0.3
    assert ckpt["train_config"] == {"strategy": "parallel"} and ckpt["best_epoch"] == 0
    model = load_model(path)
    assert model.provenance["checkpoint"] == str(path.resolve())
    assert model.provenance["dataset_source"] == {"seed": 3} and model.provenance["summary"]["test_nrmse"] == 0.3


def test_missing_file_is_a_checkpoint_error(tmp_path):
    with pytest.raises(CheckpointError, match=r"no checkpoint file at .*nope\.pt; pass the \.pt file"):
        load_model(tmp_path / "nope.pt")


def test_corrupt_file_is_a_checkpoint_error(saved, tmp_path):
    _, path = saved
    broken = tmp_path / "broken.pt"
    broken.write_bytes(path.read_bytes()[: path.stat().st_size // 2])
    with pytest.raises(CheckpointError, match="not a readable torch checkpoint"):
        load_model(broken)


@pytest.mark.parametrize("writer", ["text", "random_bytes", "foreign_torch", "unsafe_pickle"])
def test_a_file_of_another_kind_is_a_checkpoint_error(writer, tmp_path):
    path = tmp_path / "other.pt"
    if writer == "text":
        path.write_text("time,u,y\n0,1,2\n")
        match = "not a readable torch checkpoint"
    elif writer == "random_bytes":  # no Python objects in it: not told that it could run code (issue 37)
        path.write_bytes(np.random.default_rng(0).bytes(4096))
        match = r"^(?!.*(run code|weights_only)).*not an nnfmu checkpoint \(corrupt, truncated or another file type\)"
    elif writer == "foreign_torch":
        torch.save({"model": torch.zeros(3)}, path)
        match = "torch file but not an nnfmu checkpoint"
    else:
        # weights_only refuses arbitrary objects, and the message never suggests weights_only=False
        path.write_bytes(pickle.dumps(ValueError("code, not data"), protocol=2))
        match = "not a plain nnfmu checkpoint.*Do not load it with weights_only=False"
    with pytest.raises(CheckpointError, match=match):
        load_model(path)


def test_weights_that_do_not_fit_the_config_are_a_checkpoint_error(saved, tmp_path):
    _, path = saved
    ckpt = torch.load(path, weights_only=True)
    ckpt["model_config"]["hidden"] = 7
    torch.save(ckpt, tmp_path / "mismatch.pt")
    with pytest.raises(CheckpointError, match="stored weights do not fit the stored model config"):
        load_model(tmp_path / "mismatch.pt")


def test_a_failed_write_leaves_nothing_behind(tmp_path):
    blocker = tmp_path / "file"
    blocker.write_text("not a folder")
    with pytest.raises(DataFileError, match="cannot write .*m.pt: Not a directory; a part of the path is a file"):
        save_checkpoint(blocker / "m.pt", trained_like("gru"))
    assert sorted(p.name for p in tmp_path.iterdir()) == ["file"]


def test_overwriting_is_atomic(saved):
    model, path = saved
    save_checkpoint(path, trained_like("mlp"))
    assert load_model(path).config.arch == "mlp"
    assert sorted(p.name for p in path.parent.iterdir()) == ["m.pt"]
