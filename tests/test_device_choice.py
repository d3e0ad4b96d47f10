"""One device dialect: ``auto|cpu|cuda[:N]`` read, resolved, said and turned into Ray's GPUs the same way by
train, tune and reproduce. No GPU needed: torch's CUDA queries are monkeypatched."""

from __future__ import annotations

import contextlib

import pytest
import torch

from nnfmu.cli import main
from nnfmu.errors import ConfigError, TrainingError
from nnfmu.training.resources import (check_ray_device, cuda_visible, describe_device, device_name,
                                      gpus_per_training, resolve_device)


@pytest.fixture
def gpus(monkeypatch):
    """``gpus(n)``: torch sees ``n`` CUDA devices from now on (0: none)."""
    def see(n: int) -> None:
        monkeypatch.setattr(torch.cuda, "is_available", lambda: n > 0)
        monkeypatch.setattr(torch.cuda, "device_count", lambda: n)
    return see


def test_device_names_are_one_dialect():
    assert [device_name(d) for d in (None, "AUTO", " cpu", "cuda", "CUDA:01", torch.device("cuda", 1))] == \
        ["auto", "auto", "cpu", "cuda", "cuda:1", "cuda:1"]
    for bad, says in (("tpu", "unknown device 'tpu'"), ("cuda:x", "not a valid CUDA device name"),
                      ("cuda:-1", "not a valid CUDA device name"), ("cuda:", "not a valid CUDA device name")):
        with pytest.raises(ConfigError, match=says):
            device_name(bad)


def test_the_device_line_says_what_auto_chose_and_why(gpus):
    gpus(0)
    assert describe_device("auto") == "cpu (auto: no CUDA device)" and describe_device("cpu") == "cpu (asked for)"
    with pytest.raises(ConfigError, match="sees no CUDA device"):
        describe_device("cuda:1")
    gpus(2)
    assert describe_device("auto") == "cuda (auto: torch sees 2 CUDA devices; the first)"
    assert describe_device("cuda:1") == "cuda:1 (asked for)" and resolve_device("cuda:1") == torch.device("cuda", 1)
    with pytest.raises(ConfigError, match="sees 2 CUDA device"):
        resolve_device("cuda:2")


def test_gpus_follow_the_device_and_never_contradict_it():
    assert [gpus_per_training(d, 0) for d in ("cpu", "auto", "cuda", "cuda:1")] == [0, 0, 1, 1]
    assert [gpus_per_training(d, 2) for d in ("cpu", "auto", "cuda", "cuda:1")] == [0, 1, 1, 1]
    assert gpus_per_training("cuda", 0, 0.25) == 0.25 and gpus_per_training("auto", 0, 0) == 0
    with pytest.raises(ConfigError, match="--device cpu with --gpus-per-trial 1: .*drop --gpus-per-trial"):
        gpus_per_training("cpu", 2, 1)
    with pytest.raises(ConfigError, match="--device cuda:1 with --gpus-per-trial 0"):
        gpus_per_training("cuda:1", 2, 0)
    assert cuda_visible("cuda:1") == "1" and cuda_visible("cuda") is None and cuda_visible("auto") is None
    assert check_ray_device("CUDA:1", None) == "cuda:1"
    with pytest.raises(ConfigError, match="names a GPU of this machine.*use --device cuda"):
        check_ray_device("cuda:1", None, address="10.0.0.1:6379")


def test_tune_refuses_cpu_with_gpus_in_one_line(tmp_path, capsys):
    out = tmp_path / "best.json"
    assert main(["tune", "--data", str(tmp_path / "none"), "--arch", "gru", "--device", "cpu",
                 "--gpus-per-trial", "1", "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and "--device cpu with --gpus-per-trial 1" in err and not out.exists()


def test_tune_cuda_1_pins_the_local_ray_instance_to_gpu_1(valve_small, gpus, monkeypatch):
    """``tune --device cuda:1``: the local Ray instance gets GPU 1 alone, each trial reserves one GPU and trains on
    "cuda", which in the trial's process is that GPU renumbered cuda:0."""
    from ray import tune as ray_tune

    from nnfmu.study import tune as study_tune
    from nnfmu.study.tune import TuneSettings, tune_architecture

    gpus(2)
    seen: dict = {}

    @contextlib.contextmanager
    def fake_session(address, num_cpus, num_gpus=None, quiet=False, cuda_visible=None):
        seen.update(num_gpus=num_gpus, cuda_visible=cuda_visible)
        yield type("Ray", (), {"cluster_resources": staticmethod(lambda: {"CPU": 2.0, "GPU": 1.0})})

    class FakeTuner:
        def __init__(self, trainable, **kwargs):
            pass

        def fit(self):
            return []

    monkeypatch.setattr(study_tune, "ray_session", fake_session)
    monkeypatch.setattr(ray_tune, "with_parameters", lambda fn, **kw: seen.update(job=kw["job"]))
    monkeypatch.setattr(ray_tune, "with_resources", lambda t, resources: seen.update(resources=resources))
    monkeypatch.setattr(ray_tune, "Tuner", FakeTuner)
    with pytest.raises(TrainingError, match="no trial results"):  # the fake Tuner ran nothing
        tune_architecture(valve_small, "gru", settings=TuneSettings(device="cuda:1"))
    assert seen["cuda_visible"] == "1" and seen["num_gpus"] is None  # Ray detects GPU 1 only
    assert seen["resources"]["gpu"] == 1 and seen["job"]["device"] == "cuda"
    assert study_tune._local_gpus(TuneSettings()) == 0 and study_tune._local_gpus(TuneSettings(device="auto")) is None


def test_ray_session_starts_a_local_instance_with_the_chosen_gpu(monkeypatch):
    import os

    import ray

    from nnfmu.study.ray_connect import ray_session

    env: list = []
    monkeypatch.setattr(ray, "is_initialized", lambda: False)
    monkeypatch.setattr(ray, "init", lambda **kw: env.append(os.environ.get("CUDA_VISIBLE_DEVICES")))
    monkeypatch.setattr(ray, "shutdown", lambda: None)
    monkeypatch.setenv("CUDA_VISIBLE_DEVICES", "0,1")
    with ray_session(cuda_visible="1"):
        pass
    with ray_session():
        pass
    assert env == ["1", "0,1"] and os.environ["CUDA_VISIBLE_DEVICES"] == "0,1"


def test_train_auto_prints_the_device_it_chose(valve_small_dir, tmp_path, capsys, gpus):
    gpus(0)
    assert main(["train", "--data", str(valve_small_dir), "--arch", "mlp", "--device", "auto", "--epochs", "1",
                 "--hidden", "4", "--truncate", "30", "--batch-size", "16", "--quiet",
                 "--out", str(tmp_path / "m.pt")]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert lines.count("device: cpu (auto: no CUDA device)") == 1
