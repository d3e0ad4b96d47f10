"""Does the greedy selection of seeds carry beyond the validation that chose it? Cross-checked on its two halves."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from nnfmu.data import Trajectories
from nnfmu.models import EnsembleStepModel
from nnfmu.training.ensemble_select import cross_check, ensemble_score, validation_halves
from tests.test_linear_path import data, linear, path_model, rel  # noqa: F401 (fixtures)

pytestmark = pytest.mark.usefixtures("one_thread")


def shifted(model, by: float):
    """``model`` with its output moved by ``by`` (in output standard deviations) through the linear path's offset."""
    with torch.no_grad():
        model.lin_d.add_(by)
    return model


def offsets(valid: Trajectories, scale, by: float) -> Trajectories:
    """``valid`` with a measurement offset of ``+by`` output standard deviations on its even records and ``-by`` on
    its odd ones: the two halves of :func:`validation_halves` disagree on which network is best."""
    y = tuple(y + (by if i % 2 == 0 else -by) * scale for i, y in enumerate(valid.y))
    return Trajectories(valid.u, y)


def test_the_halves_are_the_records_alternately_or_one_record_cut_at_its_middle(data):  # noqa: F811
    valid = data.valid
    assert valid.n_traj >= 2
    first, second = validation_halves(valid)
    assert first.n_traj + second.n_traj == valid.n_traj
    assert all(a is b for a, b in zip(first.y, valid.y[0::2])) and all(a is b for a, b in zip(second.y, valid.y[1::2]))
    one = Trajectories(valid.u[:1], valid.y[:1])
    n = int(one.lengths[0])
    first, second = validation_halves(one)
    assert (first.lengths[0], second.lengths[0]) == (n // 2, n - n // 2)
    assert np.array_equal(np.concatenate([first.y[0], second.y[0]]), one.y[0])
    assert validation_halves(one, context=n // 2) is None  # each half needs its init window and one scored sample
    assert validation_halves(one, context=n // 2 - 1) is not None


def test_where_the_best_network_on_one_half_is_the_worst_on_the_other_the_average_carries_better(
        data, linear):  # noqa: F811
    """Networks biased up, down and not at all, on a validation whose even records read 0.3 output standard
    deviations high and whose odd ones read as much low: each half prefers the network biased its way, which is the
    worst on the other half; their average, the unbiased network, is level on both."""
    valid = offsets(data.valid, data.norm_stats("train").y_std, 0.3)
    up, plain, down = (shifted(path_model("gru", data, linear), by) for by in (0.3, 0.0, -0.3))
    check = cross_check([up, plain, down], valid)
    halves = validation_halves(valid)
    up_on, down_on = (ensemble_score([m], h)[1] for m, h in ((up, halves[1]), (down, halves[0])))
    assert check.select == pytest.approx((up_on + down_on) / 2, rel=1e-9)  # up chosen on the even records, and so on
    average = EnsembleStepModel.from_members([up, plain, down])
    assert check.average == pytest.approx(np.mean([ensemble_score([average], h)[1] for h in halves]), rel=1e-9)
    assert check.members == (1, 1) and check.averages and check.average < 0.75 * check.select
    u, y = valid.u[0], valid.y[0]
    assert rel(average.simulate(u, y[0]), path_model("gru", data, linear).simulate(u, y[0])) < 1e-9


def test_where_both_halves_rank_the_networks_alike_the_selection_carries_better(data, linear):  # noqa: F811
    plain, up, further = (shifted(path_model("gru", data, linear), by) for by in (0.0, 0.3, 0.6))
    check = cross_check([plain, up, further], data.valid)
    assert check.members == (1, 1) and not check.averages
    assert check.select < 0.5 * check.average
    assert cross_check([plain], data.valid) is None  # one network: nothing to choose
