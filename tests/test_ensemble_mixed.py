"""Mixed ensembles (networks of different architectures as one model) and the greedy selection that builds them."""

from __future__ import annotations

import copy

import pytest
import torch

from nnfmu.errors import ShapeError
from nnfmu.export import casadi_model
from nnfmu.models import EnsembleStepModel, load_model, save_checkpoint
from nnfmu.training.ensemble_select import select_ensemble
from tests.test_linear_path import data, linear, path_model, rel  # noqa: F401 (fixtures)

pytestmark = pytest.mark.usefixtures("one_thread")


def corrected(arch, data, linear, alpha, g=0.05, **options):  # noqa: F811
    """A network on the linear path with a correction that is not zero (so the members differ)."""
    model = path_model(arch, data, linear, **options)
    with torch.no_grad():
        model.alpha.copy_(torch.tensor(alpha, dtype=torch.float64))
        model.lin_G.copy_(g * torch.ones_like(model.lin_G))
    return model


def test_a_mixed_ensemble_is_its_members_mean_fed_back_in_torch_casadi_and_the_fmu(
        data, linear, tmp_path):  # noqa: F811
    from nnfmu.cosim import FmuSimulator
    from nnfmu.export import build_fmu

    members = [corrected("gru", data, linear, [0.3, -0.2]), corrected("tcn", data, linear, [-0.1, 0.2], g=-0.03),
               corrected("mlp", data, linear, [0.2, 0.1], window=3)]
    ensemble = EnsembleStepModel.from_members(members)
    assert [m.config.arch for m in ensemble.members] == ["gru", "tcn", "mlp"]
    assert len(ensemble.config.member_configs) == 3 and ensemble.n_x == sum(m.n_x for m in members)
    u, y = data.test.u[0], data.test.y[0]
    got = ensemble.simulate(u, y[0])
    assert all(rel(got, m.simulate(u, y[0])) > 1e-3 for m in members)  # not any one member
    # step by step: every member steps from its own state, and their mean is written back into each as its output
    with torch.no_grad():
        un = (torch.tensor(u) - ensemble.u_mean) / ensemble.u_std
        yn0 = (torch.tensor(y[0]) - ensemble.y_mean) / ensemble.y_std
        states = [m.init_norm(yn0[None], un[:1]) for m in members]
        for k in range(len(u) - 1):
            steps = [m.step_norm(x, un[k:k + 1]) for m, x in zip(members, states)]
            yn = torch.stack([s[1] for s in steps]).mean(0)
            states = [m.inject_y(s[0], yn) for m, s in zip(members, steps)]
            assert rel(yn[0] * ensemble.y_std + ensemble.y_mean, got[k + 1]) < 1e-12

    save_checkpoint(tmp_path / "e.pt", ensemble)
    loaded = load_model(tmp_path / "e.pt").double()  # a checkpoint loads in float32, as trained
    assert [m.config.arch for m in loaded.members] == ["gru", "tcn", "mlp"]
    from nnfmu.cli.info import describe

    assert describe(tmp_path / "e.pt")["model_config"]["member_configs"] == [
        "gru hidden 8 layers 1", "tcn hidden 8 layers 3", "mlp hidden 8 layers 2"]  # nnfmu info: each in a few words
    stored = copy.deepcopy(ensemble).float().double()
    assert rel(loaded.simulate(u, y[0]), stored.simulate(u, y[0])) < 1e-12
    assert rel(casadi_model(ensemble).simulate(u, y[0]), got) < 1e-9
    fmu = build_fmu(casadi_model(ensemble, name="mixed"), tmp_path / "mixed.fmu")
    with FmuSimulator(fmu, data.input_names, data.output_names, data.Ts) as sim:
        assert rel(sim.simulate(u, y[0]), got) < 1e-9


def test_members_must_share_their_ports_init_window_and_linear_path(data, linear):  # noqa: F811
    gru = corrected("gru", data, linear, [0.3, -0.2])
    with pytest.raises(ShapeError, match="init_window"):
        EnsembleStepModel.from_members([gru, corrected("mlp", data, linear, [0.1, 0.1], init_window=3)])
    with pytest.raises(ShapeError, match="member_configs has 1 configs for members=2"):
        gru.config.replace(members=2, member_configs=(gru.config.to_dict(),))


def test_the_selection_keeps_members_whose_errors_cancel_and_leaves_out_one_that_adds_to_them(
        data, linear):  # noqa: F811
    """Two networks biased in opposite directions (their linear path's output offset moved by +-0.3 output
    standard deviations) average to the unbiased model; a third copy of the first one would bring the bias back."""
    up, down, again = (path_model("gru", data, linear) for _ in range(3))
    with torch.no_grad():
        for model, shift in ((up, 0.3), (down, -0.3), (again, 0.3)):
            model.lin_d.add_(shift)
    selection = select_ensemble([up, again, down], data.valid)
    assert selection.chosen == [0, 2] and selection.stopped.startswith("no further member lowered")
    assert selection.scores[1] < 0.5 * selection.scores[0]
    # the third member was tried and left out: its ensemble's score is reported, above the kept one's
    from nnfmu.training.ensemble_select import ensemble_score

    assert selection.rejected == pytest.approx(ensemble_score([up, down, again], data.valid)[1], rel=1e-9)
    assert selection.rejected > 0.99 * selection.scores[-1]
    unbiased = path_model("gru", data, linear)  # the linear model: what the two average to
    u, y = data.valid.u[0], data.valid.y[0]
    assert rel(selection.model.simulate(u, y[0]), unbiased.simulate(u, y[0])) < 1e-9
    # no time left: the best candidate alone
    assert select_ensemble([up, again, down], data.valid, deadline=0.0).chosen == [0]
