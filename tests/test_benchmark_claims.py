"""The benchmark scripts behind docs/scaling.md measure what the page says they measure.

- ``train_throughput.py --compare threads`` sets the threads arm's count itself (torch's default
  under ``taskset -c 1`` is one thread, which made both arms one thread) and refuses to run it on
  fewer cores than threads;
- ``peers.py`` runs tsfast's output-feedback learner (``AR_RNNLearner``) by default, and names the
  deepSI-trained GRU for what it is (nnfmu's network under ``deepSI.fit``: deepSI has no GRU).
No timing is asserted; the peers themselves are not installed in the suite's environment.
"""

from __future__ import annotations

import importlib.util
from pathlib import Path

import pytest
import torch

BENCH = Path(__file__).resolve().parents[1] / "benchmarks"


def _load(name: str):
    spec = importlib.util.spec_from_file_location(f"bench_{name}", BENCH / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_threads_comparison_sets_both_counts_itself():
    tt = _load("train_throughput")
    from nnfmu.models import ModelConfig, build_model

    model = build_model(ModelConfig(arch="gru", n_u=1, n_y=1, hidden=2))
    before = torch.get_num_threads()
    torch.set_num_threads(1)  # as under taskset -c 1: torch's default would be one thread
    try:
        arms = tt.variants("threads", model, None, many=2)
    finally:
        torch.set_num_threads(before)
    assert sorted(threads for _, threads, _ in arms.values()) == [1, 2]


def test_threads_comparison_refuses_fewer_cores_than_threads():
    tt = _load("train_throughput")
    with pytest.raises(SystemExit, match="taskset -c 0-1"):
        tt.check_cores(2, cores={1})
    with pytest.raises(SystemExit, match="compares nothing"):
        tt.check_cores(1, cores={0, 1})
    tt.check_cores(2, cores={0, 1})


def test_peers_run_the_output_feedback_learner_and_name_the_deepsi_row_truly():
    peers, peers_train = _load("peers"), _load("peers_train")
    assert "tsfast-ar-gru" in peers.DEFAULT_CONTENDERS
    assert set(peers.CONTENDERS) - {"nnfmu"} == set(peers_train.PEERS)
    assert "deepsi-gru" not in peers.CONTENDERS  # the old name claimed a deepSI model
    assert "deepsi-fit-nnfmu-gru" in peers.DEFAULT_CONTENDERS
