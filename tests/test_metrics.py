"""NRMSE against values computed by hand (docs/design.md's scoring rule)."""

import numpy as np
import pytest

from nnfmu.errors import MetricError, ShapeError
from nnfmu.metrics import nrmse


def test_single_trajectory_hand_computed():
    # output 0: y = [1, 2, 3, 4] (mean 2.5, std ddof0 = sqrt(1.25)); errors [0, 1, 0, -1] -> RMSE sqrt(0.5)
    # output 1: y = [0, 0, 2, 2] (std 1);                     errors [0.5]*4          -> RMSE 0.5
    y = np.array([[1.0, 0.0], [2.0, 0.0], [3.0, 2.0], [4.0, 2.0]])
    p = y + np.array([[0.0, 0.5], [1.0, 0.5], [0.0, 0.5], [-1.0, 0.5]])
    r = nrmse(y, p)
    expected = np.array([np.sqrt(0.5) / np.sqrt(1.25), 0.5])
    np.testing.assert_allclose(r.per_output, [expected], rtol=1e-15)
    assert r.mean == pytest.approx(expected.mean(), rel=1e-15)
    np.testing.assert_allclose(r.output_mean, expected, rtol=1e-15)


def test_dataset_mean_is_mean_over_trajectories_of_different_length():
    y1 = np.array([[0.0], [2.0]])          # std 1
    p1 = np.array([[1.0], [2.0]])          # RMSE sqrt(0.5)
    y2 = np.array([[0.0], [0.0], [3.0]])   # std sqrt(2)
    p2 = np.array([[0.0], [0.0], [0.0]])   # RMSE sqrt(3)
    r = nrmse([y1, y2], [p1, p2])
    per = np.array([np.sqrt(0.5), np.sqrt(3.0) / np.sqrt(2.0)])
    np.testing.assert_allclose(r.per_trajectory, per, rtol=1e-15)
    assert r.mean == pytest.approx(per.mean(), rel=1e-15)


def test_mean_over_outputs_not_sum_inside_root():
    # The paper prints sqrt(sum over outputs); nnfmu averages per-output values like the robot benchmark.
    y = np.array([[0.0, 0.0], [2.0, 2.0]])
    p = y + 1.0
    r = nrmse(y, p)
    assert r.mean == pytest.approx(1.0)  # per-output NRMSE 1 each; sqrt-of-sum would give sqrt(2)


def test_perfect_prediction_scores_zero_and_json():
    y = np.random.default_rng(0).normal(size=(3, 50, 2))
    r = nrmse(y, y.copy())
    assert r.mean == 0.0
    js = r.to_json(["s", "p"])
    assert js["per_output"] == {"s": 0.0, "p": 0.0} and len(js["per_trajectory"]) == 3


def test_constant_measured_output_is_an_error():
    y = np.ones((10, 1))
    with pytest.raises(MetricError, match="constant"):
        nrmse(y, y + 0.1)


def test_non_finite_prediction_is_an_error():
    y = np.arange(10.0).reshape(-1, 1)
    p = y.copy()
    p[4] = np.nan
    with pytest.raises(MetricError, match="non-finite values in y_pred"):
        nrmse(y, p)


def test_shape_mismatch():
    with pytest.raises(ShapeError, match="y_true has shape"):
        nrmse(np.zeros((10, 2)), np.zeros((9, 2)))


def test_r2_and_mae_hand_computed():
    """R² = 1 - SSE/SST (the nonlinear-benchmarks' definition) and MAE, per output, in JSON and as means."""
    y = np.array([[1.0, 0.0], [2.0, 0.0], [3.0, 2.0], [4.0, 2.0]])
    p = y + np.array([[0.0, 0.5], [1.0, 0.5], [0.0, 0.5], [-1.0, 0.5]])
    r = nrmse(y, p)
    sse, sst = ((y - p) ** 2).sum(axis=0), ((y - y.mean(axis=0)) ** 2).sum(axis=0)  # [2, 1], [5, 4]
    assert r.r2 == pytest.approx(0.675, rel=1e-14)
    np.testing.assert_allclose(r.mae_output_mean, [0.5, 0.5], rtol=1e-15)
    js = r.to_json(["a", "b"])
    np.testing.assert_allclose([js["outputs"][k]["r2"] for k in "ab"], 1 - sse / sst, rtol=1e-14)  # [0.6, 0.75]
    assert js["r2"] == pytest.approx(0.675) and js["outputs"]["a"]["r2"] == pytest.approx(0.6)
    assert js["outputs"]["b"]["mae"] == pytest.approx(0.5) and js["trajectories"][0]["outputs"]["a"]["mae"] == 0.5
