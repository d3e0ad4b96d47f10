"""Evaluation protocols: free run from y0, after an init window, H-step-ahead; in torch and for FMUs in fmpy."""

from __future__ import annotations

import json

import numpy as np
import pytest
import torch

from nnfmu.errors import ConfigError, DataError
from nnfmu.metrics import nrmse
from nnfmu.protocols import Protocol
from tests.test_models import N_Y, make_model, random_io

pytestmark = pytest.mark.usefixtures("one_thread")


def torch_runner(model):
    def simulate(u, y0, y_past, u_past):
        return model.simulate(u, y0, **({} if y_past is None else {"y_past": y_past, "u_past": u_past}))
    return simulate


@pytest.fixture(scope="module")
def record():
    u, y = random_io(1, 120)
    return u[0].numpy(), y[0].numpy()


def test_the_default_is_the_free_run_from_y0_scored_everywhere(record):
    u, y = record
    model = make_model("gru")
    pred = Protocol().predict(torch_runner(model), u, y, 0)
    np.testing.assert_array_equal(pred, model.simulate(u, y[0]))
    assert Protocol().score([y], [pred]).mean == nrmse([y], [pred]).mean


def test_one_step_ahead_is_the_teacher_forced_prediction(record):
    """For a model whose whole state is the newest output (an MLP of window 1), restarting every sample from
    the measured output is exactly teacher forcing."""
    u, y = record
    model = make_model("mlp", window=1)
    pred = Protocol(horizon=1).predict(torch_runner(model), u, y, 0)
    with torch.no_grad():
        forced = model(torch.from_numpy(u)[None], torch.from_numpy(y[:1]), torch.from_numpy(y)[None])[0].numpy()
    np.testing.assert_allclose(pred, forced, rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize("horizon", [None, 25])
def test_init_window_runs_start_after_the_window_and_score_the_rest(record, horizon):
    u, y = record
    n = 10
    model = make_model("gru", init_window=n)
    protocol = Protocol(init_window=n, horizon=horizon)
    pred = protocol.predict(torch_runner(model), u, y, n - 1)
    assert pred.shape == (len(y) - n, N_Y) and protocol.first_scored == n
    first = model.simulate(u[n - 1:n - 1 + 26], y[n - 1], y_past=y[:n - 1], u_past=u[:n - 1])[1:]
    np.testing.assert_allclose(pred[:25], first[:25], rtol=1e-12)  # the first run: the measured window before it
    if horizon:  # the second run restarts from the measured y at sample n - 1 + 25, with its own window
        k = n - 1 + 25
        again = model.simulate(u[k:k + 26], y[k], y_past=y[k - n + 1:k], u_past=u[k - n + 1:k])[1:]
        np.testing.assert_allclose(pred[25:50], again[:25], rtol=1e-12)
    score = protocol.score([y], [pred])
    assert score.mean == pytest.approx(nrmse([y[n:]], [pred]).mean)
    assert "init window of 10 samples" in protocol.describe()


def test_bad_protocols_are_refused():
    with pytest.raises(ConfigError, match="init_window must be"):
        Protocol(init_window=0)
    with pytest.raises(ConfigError, match="horizon must be"):
        Protocol(horizon=0)
    with pytest.raises(DataError, match="leaves nothing to score"):
        Protocol(init_window=50).starts(40)


def test_evaluate_cli_scores_an_fmu_after_the_window_and_n_steps_ahead(tmp_path, valve_small_dir, valve_small):
    """``nnfmu evaluate --init-window 20 --horizon 100``: fmpy, from sample 20, restarts every 100 samples."""
    from nnfmu.cli import main
    from nnfmu.export import build_fmu, casadi_model
    from nnfmu.models import ModelConfig, build_model

    torch.manual_seed(0)
    model = build_model(ModelConfig(arch="gru", n_u=2, n_y=2, hidden=6), meta=_meta(valve_small),
                        norm=valve_small.norm_stats("train"))
    fmu = build_fmu(casadi_model(model.double(), name="gru"), tmp_path / "gru.fmu")
    assert main(["evaluate", "--data", str(valve_small_dir), str(fmu), "--init-window", "20", "--horizon", "100",
                 "--json", str(tmp_path / "s.json")]) == 0
    doc = json.loads((tmp_path / "s.json").read_text())
    assert doc["protocol"]["first_scored"] == 20 and doc["protocol"]["horizon"] == 100
    protocol = Protocol(init_window=20, horizon=100)
    test = valve_small.test
    preds = [protocol.predict(torch_runner(model), u, y, 0) for u, y in zip(test.u, test.y)]
    assert doc["models"][0]["nrmse"] == pytest.approx(protocol.score(list(test.y), preds).mean, rel=1e-9)


def _meta(ds):
    from nnfmu.training import dataset_meta

    return dataset_meta(ds, "gru")
