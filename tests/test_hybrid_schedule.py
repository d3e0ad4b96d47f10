"""A hybrid's physics in training: never worse on validation than the fit it starts from, joint or staged or frozen
(``--train-physics none``), and a ``--max-minutes`` budget that counts training, not the compiler."""

from __future__ import annotations

import dataclasses
import json
import time

import pytest
import torch

from nnfmu.cli import main
from nnfmu.data import Trajectories, save_dataset
from nnfmu.hybrid import HybridConfig
from nnfmu.models import load_checkpoint, load_model
from nnfmu.physics import resolve_physics, slider_system
from nnfmu.physics.document import system_to_document
from nnfmu.training import TrainConfig, free_run_nrmse, train
from tests.slider_cases import slider_dataset

pytestmark = pytest.mark.usefixtures("one_thread")

# A user's slider with viscous friction only; the data (tests/slider_cases.py) have Coulomb and Stribeck friction too.
VISCOUS = '''
import casadi as ca
from nnfmu.physics import PhysicsSystem
from nnfmu.system import Variable


def viscous_slider():
    x, u, p = ca.SX.sym("x", 2), ca.SX.sym("u", 1), ca.SX.sym("p", 2)
    ode = ca.Function("ode", [x, u, p], [ca.vertcat(x[1], (u[0] - p[1] * x[1]) / p[0])], ["x", "u", "p"], ["xdot"])
    output = ca.Function("output", [x, p], [x[0]], ["x", "p"], ["y"])
    y0 = ca.SX.sym("y0", 1)
    init = ca.Function("init", [y0, u, p], [ca.vertcat(y0[0], 0)], ["y0", "u0", "p"], ["x0"])
    return PhysicsSystem(name="viscous_slider", Ts=0.01, n_sub=2, ode=ode, output=output, init_state=init,
                         states=(Variable("pos", "m"), Variable("v", "m/s")), inputs=(Variable("F", "N"),),
                         outputs=(Variable("pos", "m"),), parameters=(Variable("m", "kg", "mass", 1.0),
                                                                      Variable("d", "N.s/m", "friction", 2.0)),
                         state_scales=(0.5, 1.0))
'''


@pytest.fixture(scope="module")
def slider(tmp_path_factory):
    """(dataset, its folder, ``--physics`` arguments): the viscous model as a grey-box fit left it (m 0.8, d 2.6)."""
    root = tmp_path_factory.mktemp("schedule_slider")
    ds, folder = slider_dataset(1, root)
    (root / "viscous.py").write_text(VISCOUS)
    system = resolve_physics(f"{root / 'viscous.py'}:viscous_slider")
    values = {"m": 0.8, "d": 2.6}
    fitted = dataclasses.replace(system, parameters=tuple(dataclasses.replace(v, start=values[v.name])
                                                          for v in system.parameters))
    return ds, folder, ["--physics", str(_fit_file(root / "fit.json", fitted))]


@pytest.fixture(scope="module")
def exact(slider, tmp_path_factory):
    """The slider data with a fit of the very model that made them: training can only lose to its start."""
    fit = _fit_file(tmp_path_factory.mktemp("schedule_exact") / "exact.json", slider_system())
    return slider[0], slider[1], ["--physics", str(fit)]


def _fit_file(path, system):
    """A grey-box fit result holding ``system`` (what ``nnfmu fit`` writes, without its report)."""
    path.write_text(json.dumps({"format": "nnfmu-greybox-fit/1", "physics": system_to_document(system), "fit": {}}))
    return path


@pytest.fixture(scope="module")
def valve(valve_small, tmp_path_factory):
    """(dataset, its folder, ``--physics`` arguments): the valve with spring +30 %, conductance -30 %."""
    root = tmp_path_factory.mktemp("schedule_valve")
    tr, te = valve_small.train, valve_small.test
    ds = valve_small.replace(splits={"train": tr.subset(range(4)), "valid": tr.subset([4, 5]),
                                     "test": Trajectories((te.u[0][:300],), (te.y[0][:300],))})
    params = root / "wrong.json"
    params.write_text(json.dumps({"k_s": 32500.0, "C_max": 4.2e-10, "d_c": 0.0}))
    return ds, save_dataset(ds, root / "valve"), ["--physics", "valve", "--physics-params", str(params),
                                                  "--truncate", "100"]


def _valid(model, ds) -> float:
    return free_run_nrmse(model, ds.valid, float64=True).mean


@pytest.mark.parametrize("case", ["slider", "exact", "valve"])
def test_the_hybrid_at_its_defaults_is_never_worse_on_validation_than_its_starting_fit(case, request, tmp_path,
                                                                                       capsys):
    """The kept hybrid scores at most its start (the fit, its correction at zero) on validation: on a mis-specified
    slider fit and a wrong valve, and on a fit of the true model, where any training loses; the start is then kept,
    and one line says so."""
    ds, folder, physics = request.getfixturevalue(case)
    out = tmp_path / "h.pt"
    assert main(["train", "--data", str(folder), "--arch", "hybrid", *physics, "--hidden", "4", "--epochs", "2",
                 "--quiet", "-o", str(out)]) == 0
    printed = capsys.readouterr().out
    kept, start = load_model(out), load_model(out)
    with torch.no_grad():
        for p in start.parameters():
            p.zero_()  # the correction at zero and the physical parameters as given: the fit it started from
    assert _valid(kept, ds) <= _valid(start, ds) * (1 + 1e-9)
    best = load_checkpoint(out)["best_epoch"]
    assert (best == 0) is ("the kept weights are the physics' as given, its correction at zero" in printed)
    assert (best > 0) is (f"start: the physics as given, its correction at zero, validation free-run NRMSE "
                          f"{_valid(start, ds):.4f}" in printed)  # what the hybrid gained over its start, on validation
    assert (best == 0) is (case == "exact")  # the rule was needed where training can only lose, and only there


def test_staged_freezes_the_physics_first_then_trains_it(slider):
    """``physics_schedule='staged'``: the physical parameters stay as given for the first half of the epochs, then
    move; ``joint`` moves them from the first epoch."""
    ds = slider[0]
    config = HybridConfig(n_u=1, n_y=1, hidden=4, physics=slider[2][1])
    assert config.train_physics == ("m", "d")  # a fit's free parameters train by default
    moved = {}
    for schedule in ("joint", "staged"):
        seen = []
        result = _train_recording(ds, config, schedule, seen)
        moved[schedule] = [bool(torch.any(theta != 0)) for theta in seen]
        assert result.history[-1]["epoch"] == 4
    assert moved["joint"] == [True, True, True, True]
    assert moved["staged"] == [False, False, True, True]


def _train_recording(ds, config, schedule, seen):
    """Train 4 epochs, recording the physical parameters' log scale after every epoch."""
    from nnfmu.training import trainer

    real = trainer._next_stage

    def record(session, bar, deadline):
        seen.append(session.model.physics_log_scale.detach().clone())
        real(session, bar, deadline)

    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(trainer, "_next_stage", record)
        return train(ds, config, TrainConfig(epochs=4, patience=0, dtype="float64", physics_schedule=schedule),
                     device="cpu")


@pytest.mark.parametrize("spelling", ["none", ""])
def test_train_physics_none_keeps_the_fit_as_given(slider, spelling, tmp_path):
    ds, folder, physics = slider
    out = tmp_path / "frozen.pt"
    assert main(["train", "--data", str(folder), "--arch", "hybrid", *physics, "--train-physics", spelling,
                 "--hidden", "4", "--epochs", "1", "--quiet", "-o", str(out)]) == 0
    assert load_checkpoint(out)["model_config"]["train_physics"] == []
    assert load_model(out).physics_parameter_values() == {"m": 0.8, "d": 2.6}


def test_max_minutes_counts_training_not_the_compile(slider, monkeypatch):
    """A compile slower than the whole budget (the step's C, made slow here) comes before the budget starts: the
    epochs still run, and the time it took is said."""
    from nnfmu.hybrid import fused

    real = fused._compile

    def slow_compile(model):
        time.sleep(4.0)
        return real(model)

    monkeypatch.setattr(fused, "_compile", slow_compile)
    monkeypatch.setattr(fused, "_COMPILED", {})  # compiled again, slowly
    said = []
    ds, _, physics = slider
    config = HybridConfig(n_u=1, n_y=1, hidden=4, physics=physics[1], train_physics=())
    result = train(ds, config, TrainConfig(epochs=100_000, patience=0, max_minutes=0.05, dtype="float64"),
                   device="cpu", say=said.append)
    assert result.stop_reason == "time-budget"
    assert len(result.history) - 1 >= 3  # epoch 0 is the start; a budget spent compiling would leave one epoch
    (line,) = said
    assert line.startswith("prepared the model in ") and float(line.split()[4]) >= 4.0
