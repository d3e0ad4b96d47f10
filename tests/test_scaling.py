"""Where training runs: the device option and the thread policy."""

from __future__ import annotations

import pytest
import torch

from nnfmu.cli import main
from nnfmu.errors import ConfigError
from nnfmu.models import ModelConfig
from nnfmu.training import TrainConfig, train
from nnfmu.training.resources import check_threads, resolve_device

QUICK = dict(epochs=2, batch_size=4, truncate=40, patience=0)


@pytest.fixture(scope="module")
def tiny(valve_small):
    return valve_small.replace(splits={"train": valve_small.train.subset(range(6)),
                                       "valid": valve_small.train.subset([6]),
                                       "test": valve_small.test.subset([0])})


def test_auto_takes_cuda_only_where_torch_sees_it(monkeypatch):
    monkeypatch.setattr(torch.cuda, "is_available", lambda: False)
    assert resolve_device("auto") == torch.device("cpu") == resolve_device(None)
    with pytest.raises(ConfigError, match="sees no CUDA device; use --device cpu"):
        resolve_device("cuda")
    monkeypatch.setattr(torch.cuda, "is_available", lambda: True)
    assert resolve_device("auto") == torch.device("cuda")
    with pytest.raises(ConfigError, match="unknown device 'tpu'; choose one of auto, cpu, cuda"):
        resolve_device("tpu")


@pytest.mark.skipif(torch.cuda.is_available(), reason="checks the message on a machine without CUDA")
@pytest.mark.parametrize("flags, message", [
    (["--device", "cuda"], "device 'cuda' asked for, but torch"),
    (["--threads", "0"], "--threads must be a whole number >= 1"),
])
def test_train_cli_refuses_a_missing_gpu_or_bad_threads_in_one_line(valve_small_dir, tmp_path, capsys, flags,
                                                                     message):
    out = tmp_path / "m.pt"
    assert main(["train", "--data", str(valve_small_dir), "--arch", "gru", "--out", str(out), *flags]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("nnfmu train: error: ") and message in err and "\n" not in err
    assert not out.exists()


def test_training_runs_on_one_thread_by_default_and_restores_the_callers(tiny, tmp_path):
    seen = []
    before = torch.get_num_threads()
    torch.set_num_threads(2)
    try:
        for threads in (None, 2):
            train(tiny, ModelConfig(arch="gru", n_u=2, n_y=2, hidden=4), TrainConfig(**QUICK), device="cpu",
                  threads=threads, out=tmp_path / "m.pt", callback=lambda e, m: seen.append(torch.get_num_threads()))
            assert torch.get_num_threads() == 2
    finally:
        torch.set_num_threads(before)
    assert seen == [1, 1, 2, 2]
    with pytest.raises(ConfigError, match="threads must be a positive integer"):
        check_threads(0)


def test_linear_identification_shows_the_orders_and_the_refinement_cost(tiny, capsys):
    from nnfmu.linear import identify_linear

    model = identify_linear(tiny, max_order=3, max_evaluations=3, progress=True)
    bars = capsys.readouterr().err
    assert "linear: choose the order" in bars and "order=3" in bars
    assert f"linear: refine order {model.n_x} (output error)" in bars and "cost=" in bars
    assert f"{model.info['refinement']['evaluations']}/3" in bars


def test_a_hybrid_with_compiled_physics_is_refused_on_a_gpu_in_one_line():
    from types import SimpleNamespace

    from nnfmu.training.trainer import _check_device

    hybrid = SimpleNamespace(config=SimpleNamespace(arch="hybrid", physics_backend="compiled"))
    with pytest.raises(ConfigError, match="compiled physics runs on the CPU only.*--physics-backend sx"):
        _check_device(hybrid, torch.device("cuda"))
    _check_device(hybrid, torch.device("cpu"))
    _check_device(SimpleNamespace(config=SimpleNamespace(arch="hybrid", physics_backend="sx")), torch.device("cuda"))
