"""A physics model from outside nnfmu plugs in through one registration (issue 35, docs/design.md, "Adding a
physics model").

The toy (tests/plugins/toy_physics: a first-order lag with a study of its own) is loaded as a user loads a
plug-in (``NNFMU_PLUGINS``), then goes through ``nnfmu generate``, ``nnfmu physics-fmu`` and the smoke study
with its report, with no edit inside ``nnfmu/``.
"""

from __future__ import annotations

import json
import math
import os
import sys
from pathlib import Path

import numpy as np
import pytest

from nnfmu.cli import main
from nnfmu.physics import registry

PLUGINS = Path(__file__).parent / "plugins"
pytestmark = pytest.mark.usefixtures("one_thread")


@pytest.fixture(scope="module")
def toy():
    """The toy's entry, loaded through NNFMU_PLUGINS; the registry is restored afterwards."""
    entries, env, path = dict(registry._ENTRIES), os.environ.get("NNFMU_PLUGINS"), list(sys.path)
    os.environ["NNFMU_PLUGINS"] = "toy_physics"
    sys.path.insert(0, str(PLUGINS))
    try:
        yield registry.physics_entry("toy_lag")  # unknown yet: the lookup loads the plug-ins
    finally:
        registry._ENTRIES.clear()
        registry._ENTRIES.update(entries)
        registry._loaded.discard("toy_physics")
        sys.path[:] = path
        sys.modules.pop("toy_physics", None)
        if env is None:
            os.environ.pop("NNFMU_PLUGINS", None)
        else:
            os.environ["NNFMU_PLUGINS"] = env


def _help(command: str, capsys) -> str:
    with pytest.raises(SystemExit):
        main([command, "--help"])
    return " ".join(capsys.readouterr().out.split())


def test_the_commands_offer_the_toy(toy, capsys):
    assert "toy_lag" in _help("generate", capsys) and "toy_lag standard|small" in _help("generate", capsys)
    assert "toy_lag" in _help("physics-fmu", capsys)
    assert "toy_lag" in _help("reproduce", capsys)


def test_generate_simulates_the_toy_with_the_toolkits_signals(toy, tmp_path):
    from nnfmu.data import load_dataset

    assert main(["generate", "toy_lag", "--size", "small", "-o", str(tmp_path / "ds"), "--quiet"]) == 0
    ds = load_dataset(tmp_path / "ds")
    assert (ds.input_names, ds.output_names, ds.Ts) == (["u"], ["y"], 0.1)
    assert set(ds.splits) == {"train", "valid", "test"} and ds.train.n_traj == 16
    u = np.concatenate(ds.train.u)
    assert u.min() >= -1.0 and u.max() <= 1.0 and u.std() > 0.2  # excited within the input's range
    assert main(["generate", "toy_lag", "--size", "huge", "-o", str(tmp_path / "x")]) == 2  # sizes: the entry's


def test_the_fmu_of_the_toy_follows_the_exact_step_response(toy, tmp_path):
    import fmpy

    fmu = tmp_path / "toy.fmu"
    assert main(["physics-fmu", "toy_lag", "-o", str(fmu)]) == 0
    n = 30
    signal = np.array([(0.1 * k, 1.0) for k in range(n)], dtype=[("time", float), ("u", float)])
    result = fmpy.simulate_fmu(str(fmu), input=signal, stop_time=0.1 * (n - 1), step_size=0.1,
                               output_interval=0.1, start_values={"y_start": 0.0})
    exact = [2.0 * (1.0 - math.exp(-t / 0.5)) for t in result["time"]]  # K (1 - e^(-t/T)) from rest
    np.testing.assert_allclose(result["y"], exact, atol=1e-5)  # RK4, 2 sub-steps of 50 ms


def test_the_smoke_study_of_the_toy_scores_its_physics_as_a_reference(toy, tmp_path):
    # exactly what a user types: nnfmu reproduce toy_lag --budget smoke (ten tiny networks, about 15 s)
    assert main(["reproduce", "toy_lag", "--budget", "smoke", "-o", str(tmp_path / "study"), "--quiet"]) == 0
    doc = json.loads((tmp_path / "study" / "results.json").read_text())
    physics = doc["baselines"][1]
    assert physics["label"] == "Physics model (the toy lag that generated the data, RK4)"
    assert physics["nrmse"] < 1e-6  # the generator itself, up to the FMU's arithmetic
    names = [n["name"] for n in doc["networks"]]
    assert {"gru-parallel", "gru-series-parallel", "tcn-parallel"} <= set(names) and len(names) == 10
    assert all(np.isfinite(n["nrmse"]) for n in doc["networks"])
    md = (tmp_path / "study" / "results.md").read_text()
    assert md.startswith("# Toy lag (generated data): parallel vs series-parallel training")
    assert "- The toy lag generated the data; its row is a reference." in md
