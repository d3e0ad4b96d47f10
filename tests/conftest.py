"""Shared fixtures. Generated data are made once per test session and never written to the repo."""

from __future__ import annotations

import os

import pytest

#: Modules that start Ray (a local instance or a loopback cluster): one at a time, on one worker.
RAY_MODULES = {"test_cluster.py", "test_tune.py", "test_tune_search.py"}


def pytest_configure(config):
    """Under pytest-xdist (``make test`` runs two workers on two cores), torch takes one thread per worker:
    two workers of two threads each would fight over the cores."""
    if os.environ.get("PYTEST_XDIST_WORKER"):
        import torch

        torch.set_num_threads(1)


def pytest_collection_modifyitems(config, items):
    """``--dist loadgroup``: each module runs whole on one worker (its module fixtures are built once), and
    the modules that start Ray share one group, so that no two of them run side by side on the two cores."""
    for item in items:
        name = item.path.name
        item.add_marker(pytest.mark.xdist_group("ray" if name in RAY_MODULES else name))


@pytest.fixture(scope="session")
def valve_small():
    """The small generated valve dataset (``nnfmu generate valve --size small --seed 0``)."""
    from nnfmu.physics import generate_dataset

    return generate_dataset("valve", size="small", seed=0)


@pytest.fixture(scope="session")
def valve_tiny(valve_small):
    """10 training, 2 validation and one shortened test trajectory of the small valve data."""
    from nnfmu.data import Trajectories

    tr, te = valve_small.train, valve_small.test
    return valve_small.replace(splits={"train": tr.subset(range(10)), "valid": tr.subset([10, 11]),
                                       "test": Trajectories((te.u[0][:400],), (te.y[0][:400],))})


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
