"""The linear baseline's order: chosen on shortly refined candidates, not on the subspace models alone."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.linalg

from nnfmu.cli import main
from nnfmu.data import Channel, from_arrays, save_dataset
from nnfmu.errors import ConfigError
from nnfmu.linear import LinearConfig, identify_linear
from nnfmu.linear.order import gap_orders, smallest_within


def closed_loop_pieces(seed: int = 0, piece: int = 300, noise: float = 0.01):
    """A robot-like record: an integrating axis with a resonance (4 states, Ts 0.1 s), position-controlled,
    cut into 300-sample pieces that do not start at rest; 8 pieces train, 2 validate, 2 test.

    Plant ``x'' = -0.5 x' + u`` plus a mode at 3 rad/s (damping 0.05); the controller feeds the noisy
    position back (``u = (r - y) - 2 dy + 0.5 e``), so the input depends on the output noise.
    """
    Ac = np.array([[0, 1, 0, 0], [0, -0.5, 0, 0], [0, 0, 0, 1], [0, 0, -9.0, -0.3]])
    Bc = np.array([[0], [1.0], [0], [9.0]])
    C = np.array([[1.0, 0, 1.0, 0]])
    M = scipy.linalg.expm(np.block([[Ac, Bc], [np.zeros((1, 5))]]) * 0.1)
    A, B = M[:4, :4], M[:4, 4:]
    rng = np.random.default_rng(seed)
    n = 12 * piece
    ref = np.repeat(rng.normal(size=n // 30 + 1), 30)[:n]
    x, y_prev, u, y = np.zeros(4), 0.0, np.empty((n, 1)), np.empty((n, 1))
    for k in range(n):
        y[k] = C @ x + noise * rng.normal()
        u[k] = (ref[k] - y[k]) - 2.0 * (y[k] - y_prev) + 0.5 * rng.normal()
        y_prev, x = y[k, 0], A @ x + B @ u[k]
    pieces = [(u[i * piece:(i + 1) * piece], y[i * piece:(i + 1) * piece]) for i in range(12)]
    split = {"train": pieces[:8], "valid": pieces[8:10], "test": pieces[10:]}
    arrays = {f"{a}_{name}": [p[i] for p in ps] for name, ps in split.items() for i, a in enumerate("uy")}
    return from_arrays(Ts=0.1, **arrays, input_names=[Channel("torque", "N.m")], output_names=[Channel("q", "deg")])


@pytest.fixture(scope="module")
def robot_like():
    return closed_loop_pieces()


def test_order_is_chosen_after_refinement_where_every_subspace_model_is_poor(robot_like):
    """The robot's failure in small: every subspace model runs worse than the mean on validation, the
    least bad is order 1, and ranking the subspace models alone (``order_candidates=1``, the old rule)
    keeps it. Refined shortly, the true order 4 is clearly better, and is chosen."""
    old = identify_linear(robot_like, order_candidates=1, max_evaluations=200)
    assert min(old.info["order_scores"].values()) > 1.0 and old.n_x == 1 and old.info["order_candidates"] == {}
    new = identify_linear(robot_like, max_evaluations=200)
    candidates = {int(n): v for n, v in new.info["order_candidates"].items()}
    assert new.n_x == 4 and 1 in candidates and 4 in candidates and len(candidates) <= 4
    assert candidates[4] < candidates[1] - 0.1
    assert new.info["nrmse_valid"] <= candidates[4] < old.info["nrmse_valid"] - 0.1  # never worse than its start
    report = new.info["refinement"]
    assert report["accepted"] and 0 < report["short_evaluations"] <= 20 < report["evaluations"] <= 200 + 20


def test_without_a_validation_split_the_subspace_scores_decide(robot_like, monkeypatch):
    """On the training data the candidates were refined on, more states always look better: no short
    refinements there, one refinement of the order the subspace models chose."""
    import nnfmu.linear.identify as identify

    calls, real_refine = [], identify.refine

    def spy(start, *args, **kwargs):
        calls.append(start.n_x)
        return real_refine(start, *args, **kwargs)

    monkeypatch.setattr(identify, "refine", spy)
    no_valid = robot_like.replace(splits={k: v for k, v in robot_like.splits.items() if k != "valid"})
    model = identify_linear(no_valid, max_evaluations=50)
    assert model.info["scored_on"] == "train" and model.info["order_candidates"] == {}
    assert calls == [model.n_x]
    calls.clear()
    model = identify_linear(robot_like, max_evaluations=50, refit=False)  # the choice, before a refit
    assert sorted(calls[:-1]) == sorted(int(n) for n in model.info["order_candidates"]) and calls[-1] == 4


def test_gap_orders_and_the_tolerance_rule():
    sv = np.array([10.0, 9.0, 1.0, 0.9, 1e-12, 1e-13])
    assert gap_orders(sv, 20, 2) == [4, 2]  # the last supported order has an infinite gap
    assert gap_orders(sv, 3, 3) == [2, 1, 3]  # ties in order of size; none beyond max_order
    assert gap_orders(sv, 20, 0) == []
    assert smallest_within({1: 1.0, 4: 0.5, 6: 0.495}, 0.02) == 4
    assert smallest_within({1: 0.5, 4: 0.5}, 0.0) == 1
    with pytest.raises(ConfigError, match="order_candidates must be a positive integer"):
        LinearConfig(order_candidates=0)


def test_cli_prints_the_candidates_and_checks_the_option(robot_like, tmp_path, capsys):
    data = save_dataset(robot_like, tmp_path / "data")
    out_file = tmp_path / "m.json"
    assert main(["linear", "--data", str(data), "--max-evaluations", "100", "--quiet", "--save", str(out_file)]) == 0
    out = capsys.readouterr().out
    assert "(up to 4 compared after 10 refinement evaluations each)" in out
    assert "order 4 (chosen on the valid split, among 1: " in out and "shortly refined" in out
    assert main(["linear", "--data", str(data), "--order-candidates", "0", "--save", str(tmp_path / "x.json")]) == 2
    assert "--order-candidates" in capsys.readouterr().err and not (tmp_path / "x.json").exists()
