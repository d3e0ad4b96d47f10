"""Hybrids on any physics model: the registered slider, a user's model file outside the repository, a fit result.

- with its correction zero, a hybrid is exactly its physics (an RK4 free run, tests/physics_sim.py), in torch with
  either physics backend and in its FMU; on a grey-box fit result that is the fitted model;
- a hybrid on ``FILE.py:NAME`` trains jointly with the model's free parameters, and its checkpoint holds the
  physics as a document: after the file is deleted it loads, scores and exports to an FMU that fmpy validates,
  that simulates as co-simulation and Model Exchange, and whose directional derivatives are finite differences;
- an ODE that blows up in training stops it with a message and never leaves non-finite weights behind.
"""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest
import torch
from fmpy.validation import validate_fmu
from physics_sim import simulate_states
from slider_cases import model_exchange_and_co_simulation, slider_dataset
from test_fmu_model_exchange import MeInstance

from nnfmu.cli import main
from nnfmu.cosim import FmuSimulator
from nnfmu.errors import ShapeError, TrainingError
from nnfmu.export import build_fmu, casadi_model
from nnfmu.hybrid import HybridConfig, HybridStepModel, physics_system
from nnfmu.models import build_model, load_checkpoint, load_model
from nnfmu.physics import PhysicsSystem, resolve_physics
from nnfmu.physics.document import system_to_document
from nnfmu.training import TrainConfig, train
from nnfmu.training.evaluate import score

pytestmark = pytest.mark.usefixtures("one_thread")

# A user's model file, written with plain CasADi: the slider with viscous friction only (the built-in slider
# also has Coulomb and Stribeck friction, which the data below have); the same with quadratic friction under
# the same model name; and a model that blows up in finite time (xdot = a x^2 + u).
MODEL_FILE = '''
import casadi as ca
from nnfmu.physics import PhysicsSystem
from nnfmu.system import Variable


def _system(name, friction, parameters):
    x, u, p = ca.SX.sym("x", 2), ca.SX.sym("u", 1), ca.SX.sym("p", 2)
    ode = ca.Function("ode", [x, u, p], [ca.vertcat(x[1], (u[0] - friction(x[1], p[1])) / p[0])],
                      ["x", "u", "p"], ["xdot"])
    output = ca.Function("output", [x, p], [x[0]], ["x", "p"], ["y"])
    y0 = ca.SX.sym("y0", 1)
    init = ca.Function("init", [y0, u, p], [ca.vertcat(y0[0], 0)], ["y0", "u0", "p"], ["x0"])
    return PhysicsSystem(name=name, Ts=0.01, n_sub=2, ode=ode, output=output, init_state=init,
                         states=(Variable("pos", "m"), Variable("v", "m/s")),
                         inputs=(Variable("F", "N", "force", min=-6.0, max=6.0),),
                         outputs=(Variable("pos", "m"),), parameters=parameters, state_scales=(0.5, 1.0))


def viscous_slider():
    return _system("viscous_slider", lambda v, d: d * v,
                   (Variable("m", "kg", "mass", 1.0, min=0.2, max=1.2), Variable("d", "N.s/m", "friction", 2.0)))


def quadratic_slider():
    return _system("viscous_slider", lambda v, d: d * v * ca.fabs(v),
                   (Variable("m", "kg", "mass", 1.0), Variable("d", "N.s2/m2", "friction", 2.0)))


def exploding():
    x, u, p = ca.SX.sym("x", 1), ca.SX.sym("u", 1), ca.SX.sym("p", 1)
    ode = ca.Function("ode", [x, u, p], [p[0] * x[0] ** 2 + u[0]], ["x", "u", "p"], ["xdot"])
    output = ca.Function("output", [x, p], [x], ["x", "p"], ["y"])
    y0 = ca.SX.sym("y0", 1)
    init = ca.Function("init", [y0, u, p], [y0], ["y0", "u0", "p"], ["x0"])
    return PhysicsSystem(name="exploding", Ts=0.01, n_sub=1, ode=ode, output=output, init_state=init,
                         states=(Variable("pos", "m"),), inputs=(Variable("F", "N"),), outputs=(Variable("pos", "m"),),
                         parameters=(Variable("a", "1/(m.s)", "growth", 1e4),))
'''


@pytest.fixture(scope="module")
def model_file(tmp_path_factory):
    path = tmp_path_factory.mktemp("user_model") / "my_slider.py"  # pytest's temporary folder: outside the repo
    path.write_text(MODEL_FILE)
    return path


@pytest.fixture(scope="module")
def data(tmp_path_factory):
    """The built-in slider (Stribeck friction) under piecewise-constant forces: 6 x 120 train, 2 valid, 1 test."""
    return slider_dataset(0, tmp_path_factory.mktemp("slider_data"))


def physics_run(system: PhysicsSystem, u: np.ndarray, y0: np.ndarray) -> np.ndarray:
    """Outputs (N, n_y) of the physics' own RK4 free run from ``init_state(y0, u[0])``."""
    p = system.parameter_values()
    x0 = np.asarray(system.init_state(y0, u[0], p)).ravel()
    xs = simulate_states(system, x0, u[:-1])
    return np.stack([np.asarray(system.output(x, p)).ravel() for x in xs])


def _relative(got: np.ndarray, want: np.ndarray) -> float:
    return float(np.max(np.abs(got - want)) / np.ptp(want))


def fitted(system: PhysicsSystem, **values) -> PhysicsSystem:
    """``system`` with the given nominal parameter values: what a grey-box fit writes."""
    parameters = tuple(dataclasses.replace(v, start=values.get(v.name, v.start)) for v in system.parameters)
    return dataclasses.replace(system, parameters=parameters)


@pytest.fixture(scope="module")
def fit_file(model_file):
    path = model_file.parent / "fit.json"
    system = fitted(resolve_physics(f"{model_file}:viscous_slider"), m=0.8, d=2.6)
    path.write_text(json.dumps({"format": "nnfmu-greybox-fit/1", "physics": system_to_document(system), "fit": {}}))
    return path


@pytest.mark.parametrize("backend", ["compiled", "sx"])
@pytest.mark.parametrize("which", ["slider", "viscous", "quadratic", "fit"])
def test_a_zero_correction_is_exactly_the_physics(which, backend, model_file, fit_file, data):
    # the user's systems themselves, two ODEs under one name: each hybrid must run its own (not a cached other)
    spec = {"slider": "slider", "viscous": resolve_physics(f"{model_file}:viscous_slider"), "fit": str(fit_file),
            "quadratic": resolve_physics(f"{model_file}:quadratic_slider")}[which]
    ds, _ = data
    model = build_model(HybridConfig(n_u=1, n_y=1, physics=spec, hidden=8, physics_backend=backend), ds.meta(),
                        norm=ds.norm_stats("train")).double()
    if which == "fit":  # the fit's values are the hybrid's starting point, and what it trains by default
        assert model.physics_parameter_values() == {"m": 0.8, "d": 2.6}
        assert model.config.train_physics == ("m", "d")
    u, y = ds.test.u[0], ds.test.y[0]
    want = physics_run(resolve_physics(spec), u, y[0])
    assert np.ptp(want) > 0.05
    assert _relative(model.simulate(u, y[0]), want) < 1e-13


def test_both_backends_give_the_same_gradients_on_a_users_model(model_file, data):
    ds, _ = data
    u = torch.tensor(ds.test.u[0][None, :40])
    y = torch.tensor(ds.test.y[0][None, :40])
    grads = []
    for backend in ("compiled", "sx"):
        torch.manual_seed(0)
        config = HybridConfig(n_u=1, n_y=1, physics=f"{model_file}:quadratic_slider", hidden=4, physics_backend=backend)
        model = build_model(config, ds.meta(), norm=ds.norm_stats("train")).double()
        with torch.no_grad():
            for prm in model.correction.parameters():
                prm.copy_(0.3 * torch.randn(prm.shape, dtype=torch.float64))
            model.physics_log_scale.fill_(0.01)
        (model(u, y[:, 0]) - y).pow(2).mean().backward()
        grads.append(torch.cat([p.grad.reshape(-1) for p in model.parameters() if p.grad is not None]))
    assert grads[0].abs().max() > 0 and grads[0].numel() == grads[1].numel()
    torch.testing.assert_close(grads[1], grads[0], rtol=1e-10, atol=1e-12 * float(grads[0].abs().max()))


def test_a_zero_step_correction_is_exactly_the_physics_too(model_file, data):
    ds, _ = data
    system = resolve_physics(f"{model_file}:viscous_slider")
    model = HybridStepModel(HybridConfig(n_u=1, n_y=1, physics=system, hidden=4, correction="step"), ds.meta())
    u, y = ds.test.u[0], ds.test.y[0]
    assert _relative(model.double().simulate(u, y[0]), physics_run(system, u, y[0])) < 1e-13


def test_a_stored_hybrid_config_from_before_the_registry_still_loads():
    old = {"arch": "hybrid", "n_u": 1, "n_y": 1, "hidden": 8, "layers": 2, "window": 1, "activation": "tanh",
           "dropout": 0.0, "physics": "slider", "physics_params": {"d": 2.5}, "train_physics": ["d"],
           "train_physics_gain": 10.0, "correction": "derivative", "corrected_states": ["v"],
           "correction_time": 0.1, "n_sub": None, "physics_backend": "compiled"}
    config = HybridConfig.from_dict(old)
    assert config.physics_document is None and config.parameter_values()[:2] == [1.0, 2.5]
    assert {k: v for k, v in config.to_dict().items() if k in old} == old


def test_defaults_come_from_the_registry_or_cover_every_state(model_file):
    slider = HybridConfig(n_u=1, n_y=1, physics="slider")
    assert (slider.corrected_states, slider.correction_time, slider.train_physics) == (("v",), 0.1, ())
    assert "physics_document" not in slider.to_dict()  # a registered model's checkpoint stays as it was
    user = HybridConfig(n_u=1, n_y=1, physics=f"{model_file}:viscous_slider")
    assert (user.corrected_states, user.correction_time, user.train_physics) == (("v",), 0.1, ("m", "d"))  # pos: kinematic
    assert HybridConfig.from_dict(json.loads(json.dumps(user.to_dict()))) == user
    assert len(repr(user)) < 1000  # error messages quote configs: not the serialized model
    assert user.replace(physics="slider", corrected_states=None).system() is physics_system("slider")  # not the file's
    with pytest.raises(ShapeError, match="has n_u = 1, got 2"):
        HybridConfig(n_u=2, n_y=1, physics=f"{model_file}:viscous_slider")


def test_trained_parameters_stay_within_their_bounds(model_file):
    model = HybridStepModel(HybridConfig(n_u=1, n_y=1, physics=f"{model_file}:viscous_slider"))
    with torch.no_grad():
        model.physics_log_scale.fill_(1.0)  # m * exp(10) and d * exp(10): m has max 1.2, d no bound
    values = model.physics_parameter_values()
    assert values["m"] == 1.2 and values["d"] == pytest.approx(2.0 * np.exp(10.0))


@pytest.fixture(scope="module")
def trained(model_file, data, tmp_path_factory):
    """``nnfmu train --arch hybrid --physics FILE.py:NAME`` for 2 epochs; the model file is deleted afterwards."""
    folder = tmp_path_factory.mktemp("user_hybrid")
    own, out = folder / "slider_model.py", folder / "hybrid.pt"
    own.write_text(model_file.read_text())
    assert main(["train", "--data", str(data[1]), "--arch", "hybrid", "--physics", f"{own}:viscous_slider",
                 "--hidden", "8", "--epochs", "2", "--truncate", "40", "--batch-size", "3", "--quiet",
                 "-o", str(out)]) == 0
    own.unlink()
    return load_checkpoint(out), out


def test_the_correction_trains_jointly_with_the_free_parameters(trained):
    ckpt, path = trained
    history = ckpt["history"]
    assert ckpt["model_config"]["train_physics"] == ["m", "d"]  # the model's free parameters, by default
    assert ckpt["best_epoch"] > 0 and history[ckpt["best_epoch"]]["valid_nrmse"] < history[0]["valid_nrmse"]
    values = load_model(path).physics_parameter_values()
    assert values["m"] != 1.0 and values["d"] != 2.0


def test_the_checkpoint_loads_and_scores_without_the_model_file(trained, data):
    ckpt, path = trained
    assert ckpt["model_config"]["physics_document"]["format"] == "nnfmu-physics/1"  # JSON, read weights_only
    model = load_model(path)
    assert isinstance(model, HybridStepModel) and model.physics.name == "viscous_slider"
    # the score the training wrote (float64 weights) and the reloaded model's (float32 weights, as every network)
    assert score(model, data[0].test) == pytest.approx(ckpt["summary"]["test_nrmse"], rel=1e-5)


def test_info_names_the_stored_physics_instead_of_printing_it(trained, capsys):
    assert main(["info", str(trained[1])]) == 0
    out = capsys.readouterr().out
    assert "physics_document viscous_slider (2 states; stored inside)" in " ".join(out.split())
    assert len(out) < 3000  # not the serialized CasADi functions (about 6000 characters)


@pytest.fixture(scope="module")
def trained_fmu(trained):
    _, path = trained
    fmu = path.with_suffix(".fmu")
    assert main(["export", str(path), "-o", str(fmu), "--fmi-version", "3"]) == 0  # the model file is gone
    return fmu


def test_the_fmu_validates_and_co_simulates_as_the_model(trained, trained_fmu, data, tmp_path, capsys):
    assert validate_fmu(str(trained_fmu)) == []
    ds, folder = data
    model = load_model(trained[1])
    u, y = np.concatenate(ds.test.u + ds.valid.u), ds.test.y[0]
    with FmuSimulator(trained_fmu, ds.input_names, ds.output_names, ds.Ts) as sim:
        got = sim.simulate(u, y[0])
    assert _relative(got, model.simulate(u, y[0])) < 1e-10
    assert main(["evaluate", str(trained_fmu), "--data", str(folder), "--json", str(tmp_path / "s.json")]) == 0
    scores = json.loads((tmp_path / "s.json").read_text())
    assert np.isfinite(json.dumps(scores).count("nrmse"))


def test_model_exchange_integrates_and_its_jacobian_is_finite_differences(trained_fmu):
    me = MeInstance(trained_fmu, {"pos_start": 0.05})
    me.set({"F": 2.0})
    x = me.states_now() + np.array([0.01, 0.3])
    me.set_states(x)
    unknowns, knowns = [f"der({s})" for s in me.states] + ["pos"], [*me.states, "F"]
    jacobian = me.jacobian(unknowns, knowns)
    fd = me.finite_differences(unknowns, {"F": 2.0}, floor=1e-3)
    np.testing.assert_array_less(np.abs(jacobian - fd) / np.abs(jacobian).max(axis=1, keepdims=True), 1e-6)
    assert np.count_nonzero(jacobian) >= 4
    me.fmu.terminate()
    me.fmu.freeInstance()


def test_model_exchange_follows_co_simulation(trained_fmu, data):
    ds, _ = data
    runs = model_exchange_and_co_simulation(trained_fmu, ds, ds.test.u[0][:60], ds.test.y[0][0])
    assert np.ptp(runs["CoSimulation"]) > 0.01  # the run moves
    # CVode integrates the hybrid's ODE; co-simulation is its RK4 (2 sub-steps of 5 ms): RK4's error (measured 1.6e-8)
    assert _relative(runs["ModelExchange"], runs["CoSimulation"]) < 1e-6


def test_the_fmu_of_a_zero_correction_is_exactly_the_physics(model_file, data, tmp_path):
    ds, _ = data
    spec = f"{model_file}:viscous_slider"
    model = build_model(HybridConfig(n_u=1, n_y=1, physics=spec, hidden=4), ds.meta(), norm=ds.norm_stats("train"))
    fmu = build_fmu(casadi_model(model.double()), tmp_path / "zero.fmu", fmi_version=2)
    u, y = ds.test.u[0], ds.test.y[0]
    with FmuSimulator(fmu, ds.input_names, ds.output_names, ds.Ts) as sim:
        got = sim.simulate(u, y[0])
    assert _relative(got, physics_run(resolve_physics(spec), u, y[0])) < 1e-12


def test_an_ode_that_blows_up_stops_training_and_keeps_finite_weights(model_file, data, tmp_path):
    config = HybridConfig(n_u=1, n_y=1, physics=f"{model_file}:exploding", hidden=4)
    out = tmp_path / "exploding.pt"
    with pytest.raises(TrainingError, match="loss became (nan|inf).*best weights so far are kept"), \
            pytest.warns(RuntimeWarning, match="exploding hybrid's simulation became non-finite.*ODE blew up.*a = 1e"):
        train(data[0], config, TrainConfig(epochs=2, truncate=20, batch_size=3, dtype="float64"), out=out)

    def tensors(value):
        if isinstance(value, torch.Tensor):
            yield value
        elif isinstance(value, dict):
            for v in value.values():
                yield from tensors(v)
        elif isinstance(value, (list, tuple)):
            for v in value:
                yield from tensors(v)

    ckpt = load_checkpoint(out)
    weights = list(tensors(ckpt))
    assert weights and all(torch.isfinite(t).all() for t in weights if t.is_floating_point())
