"""Studies and searches spread over processes and machines: ``--jobs``, and a real two-node Ray cluster on
127.0.0.1 (``ray.cluster_utils.Cluster``), giving the results of the sequential local run for the same seeds."""

from __future__ import annotations

import json

import pytest

from nnfmu.cli import main
from nnfmu.study import get_budget, reproduce

#: The same float32 training in two processes: the compiled free run and torch's agree to rounding, and a process
#: runs torch's where its C library is unavailable (seen once in a full suite on a fresh machine: 1.5e-7 apart after
#: 2 epochs). Another configuration, seed or length differs by far more.
SAME_TRAINING = 1e-6
# one network and the baselines: the same cells as the session's smoke study, for a fraction of its time
GRU_ONLY = get_budget("valve", "smoke").replace(archs=("gru",), strategies=("parallel",))


def _scores(doc: dict) -> dict:
    return {row["name"]: row["nrmse"] for row in doc["networks"] + doc["baselines"]}


@pytest.fixture(scope="module")
def cluster():
    """Two Ray nodes of one CPU each, both bound to 127.0.0.1; stopped by their handle at the end."""
    from ray.cluster_utils import Cluster

    nodes = Cluster(initialize_head=True, head_node_args={"num_cpus": 1, "node_ip_address": "127.0.0.1",
                                                          "include_dashboard": False})
    try:
        nodes.add_node(num_cpus=1, node_ip_address="127.0.0.1")
        yield nodes
    finally:
        nodes.shutdown()


def test_jobs_run_cells_side_by_side_with_the_sequential_results(smoke_study, tmp_path):
    lines: list[str] = []
    result = reproduce("valve", tmp_path / "study", budget=GRU_ONLY, jobs=2, progress=False, echo=lines.append)
    local = _scores(smoke_study[1].results)
    assert {k: local[k] for k in _scores(result.results)} == _scores(result.results)
    assert set(result.log.ran) == {c for c in smoke_study[1].log.ran if "gru parallel" in c or "gru-parallel" in c
                                   or "linear" in c or "physics" in c or c.startswith(("data", "write"))}
    again = reproduce("valve", tmp_path / "study", budget=GRU_ONLY, jobs=2, progress=False, echo=None)
    assert again.log.ran == []  # resumable as a sequential run


def test_tune_on_a_loopback_cluster_with_asha_reports_the_best(cluster, valve_small_dir, tmp_path, capsys):
    best_file = tmp_path / "best.json"
    assert main(["tune", "--data", str(valve_small_dir), "--arch", "gru", "--grid", "hidden=4,8", "--epochs", "2",
                 "--budget", "smoke", "--address", cluster.address, "--scheduler", "asha", "--device", "cpu",
                 "--storage", str(tmp_path / "ray"), "--out", str(best_file)]) == 0
    printed = capsys.readouterr().out
    doc = json.loads(best_file.read_text())
    assert "2 trials of gru (parallel; grid search, asha scheduler)" in printed
    assert all(t["error"] is None and t["epochs"] in (1, 2) for t in doc["trials"])
    # every trial scored what a local training of its configuration and length gives
    from nnfmu.data import load_dataset
    from nnfmu.training import train

    base = get_budget("valve", "smoke").hyper["gru"]
    for trial in doc["trials"]:
        hyper = base.replace(hidden=trial["hidden"])
        local = train(load_dataset(valve_small_dir), hyper.model_config("gru", 2, 2),
                      hyper.train_config(strategy="parallel", epochs=trial["epochs"], patience=0, seed=0,
                                         max_minutes=None), device="cpu")
        assert trial["best_valid_nrmse"] == pytest.approx(local.best_valid_nrmse, rel=SAME_TRAINING)


def test_smoke_study_as_ray_tasks_equals_the_local_run(cluster, smoke_study, tmp_path):
    out = tmp_path / "study"
    result = reproduce("valve", out, budget=GRU_ONLY, address=cluster.address, progress=False, echo=None)
    local = _scores(smoke_study[1].results)
    assert _scores(result.results) == pytest.approx({k: local[k] for k in _scores(result.results)}, rel=SAME_TRAINING)
    assert (out / "fmus" / "gru-parallel.fmu").is_file() and (out / "results.md").is_file()


def test_without_an_address_a_local_instance_starts_beside_a_running_cluster_and_leaves_it_running(cluster,
                                                                                                     monkeypatch):
    """With a cluster running on this machine (``ray start`` records it; ``RAY_ADDRESS`` names it), ``nnfmu tune``
    without --address raised Ray's ValueError (num_cpus given while joining a cluster). It starts its own instance
    with the CPUs it asks for, and the user's cluster runs on.

    Last in this module: a local instance started in this process before a study on the cluster made the cluster's
    tasks fail with Ray's OwnerDiedError (before this change too)."""
    from nnfmu.study.ray_connect import ray_session

    monkeypatch.setenv("RAY_ADDRESS", cluster.address)
    with ray_session(num_cpus=3, quiet=True) as ray:
        assert ray.cluster_resources()["CPU"] == 3 and len(ray.nodes()) == 1  # not the cluster's 2 nodes of 1 CPU
    assert not ray.is_initialized()
    assert all(node.remaining_processes_alive() for node in cluster.list_all_nodes())
