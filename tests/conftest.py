"""Shared fixtures. Generated data are made once per test session and never written to the repo."""

from __future__ import annotations

import pytest


@pytest.fixture(scope="session")
def valve_small():
    """The small generated valve dataset (``nnfmu generate valve --size small --seed 0``)."""
    from nnfmu.physics import generate_dataset

    return generate_dataset("valve", size="small", seed=0)


@pytest.fixture(scope="session")
def valve_small_dir(valve_small, tmp_path_factory):
    """``valve_small`` saved as a dataset folder; returns its path."""
    from nnfmu.data import save_dataset

    return save_dataset(valve_small, tmp_path_factory.mktemp("data") / "valve_small")


@pytest.fixture(scope="module")
def one_thread():
    """Torch on one thread for a module of tiny models: extra threads only add contention (and two
    pytest processes would fight over the cores). Use with ``pytestmark = pytest.mark.usefixtures("one_thread")``."""
    from nnfmu.models.base import torch_threads

    with torch_threads(1):
        yield


@pytest.fixture(scope="session")
def smoke_study(tmp_path_factory):
    """``nnfmu reproduce valve --budget smoke``, run once per session; returns (folder, result, printed lines)."""
    from nnfmu.study import reproduce

    out = tmp_path_factory.mktemp("study") / "valve-smoke"
    lines: list[str] = []
    result = reproduce("valve", out, budget="smoke", progress=False, echo=lines.append)
    return out, result, lines
