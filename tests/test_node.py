"""The neural ODE (``--arch node``): a hybrid with no physics, trained by the free run, exported with Model Exchange.

- the generated physics is a zero ODE whose output is the first states in the data's units: an untrained node
  holds its first output, and its initial state is the measured output, normalised;
- ``nnfmu train --arch node`` trains it (validation free-run NRMSE falls) and writes a checkpoint that
  ``nnfmu export`` turns into an FMU that fmpy validates; the FMU's co-simulation is the torch free run (1e-10),
  Model Exchange with CVode follows co-simulation, and its directional derivatives are finite differences;
- bad sizes get one line and status 2, and nothing is written.
"""

from __future__ import annotations

import contextlib
import io

import numpy as np
import pytest
from fmpy.validation import validate_fmu
from slider_cases import model_exchange_and_co_simulation, slider_dataset
from test_fmu_model_exchange import MeInstance

from nnfmu.cli import main
from nnfmu.cosim import FmuSimulator
from nnfmu.errors import ShapeError
from nnfmu.hybrid import HybridStepModel
from nnfmu.models import build_model, load_checkpoint, load_model
from nnfmu.export import casadi_model
from nnfmu.node import NodeConfig, node_physics


pytestmark = pytest.mark.usefixtures("one_thread")


@pytest.fixture(scope="module")
def data(tmp_path_factory):
    """The slider (Stribeck friction) under piecewise-constant forces: 6 x 120 train, 2 valid, 1 test (Ts 10 ms)."""
    return slider_dataset(1, tmp_path_factory.mktemp("slider_data"))


def _relative(got: np.ndarray, want: np.ndarray) -> float:
    return float(np.max(np.abs(got - want)) / np.ptp(want))


def test_the_generated_physics_is_a_zero_ode_read_out_in_the_datas_units():
    system = node_physics(5, 2, 2)
    assert [v.name for v in system.states] == ["x1", "x2", "x3", "x4", "x5"]
    assert [v.name for v in system.parameters] == ["y1_mean", "y2_mean", "y1_std", "y2_std"]
    p = [1.0, -2.0, 0.5, 4.0]
    x0 = np.asarray(system.init_state([2.0, 6.0], [0.3, 0.1], p)).ravel()
    np.testing.assert_allclose(x0, [2.0, 2.0, 0.0, 0.0, 0.0])  # (y0 - mean) / std, the latent states 0
    np.testing.assert_allclose(np.asarray(system.output(x0, p)).ravel(), [2.0, 6.0])
    assert not np.asarray(system.ode(x0 + 1.0, [0.3, 0.1], p)).any()


def test_an_untrained_node_holds_its_first_output_and_its_config_round_trips(data):
    ds, _ = data
    config = NodeConfig(n_u=1, n_y=1, hidden=8)
    assert (config.n_states, config.train_physics, config.corrected_states) == (4, (), ("x1", "x2", "x3", "x4"))
    assert NodeConfig.from_dict(config.to_dict()) == config
    model = build_model(config, ds.meta(), norm=ds.norm_stats("train")).double()
    assert isinstance(model, HybridStepModel) and model.n_x == 4
    u, y = ds.test.u[0], ds.test.y[0]
    np.testing.assert_array_equal(model.simulate(u, y[0]), np.repeat(y[:1], len(u), axis=0))
    with pytest.raises(ShapeError, match="at least one state per output"):
        NodeConfig(n_u=1, n_y=3, n_states=2)


@pytest.fixture(scope="module")
def trained(data, tmp_path_factory):
    """``nnfmu train --arch node --states 3`` for 3 epochs, then ``nnfmu export`` (FMI 3)."""
    out, printed = tmp_path_factory.mktemp("node") / "node.pt", io.StringIO()
    with contextlib.redirect_stdout(printed):
        assert main(["train", "--data", str(data[1]), "--arch", "node", "--states", "3", "--hidden", "8",
                     "--epochs", "3", "--truncate", "40", "--quiet", "-o", str(out)]) == 0
    fmu = out.with_suffix(".fmu")
    assert main(["export", str(out), "-o", str(fmu), "--fmi-version", "3"]) == 0
    return load_checkpoint(out), out, fmu, printed.getvalue()


def test_the_cli_trains_it_by_the_free_run_with_the_batch_planned_from_the_data(trained):
    ckpt, path, _, printed = trained
    # 6 trajectories of 120 samples in windows of 40: 18 windows an epoch, a batch of a quarter of them
    assert "plan: batch: 4 of 18 windows an epoch" in printed and ckpt["train_config"]["batch_size"] == 4
    history = ckpt["history"]
    assert ckpt["model_config"]["arch"] == "node" and ckpt["model_config"]["n_states"] == 3
    assert ckpt["best_epoch"] > 0 and history[ckpt["best_epoch"]]["valid_nrmse"] < history[0]["valid_nrmse"]
    assert load_model(path).n_x == 3


def test_the_fmu_validates_and_co_simulates_as_the_torch_free_run(trained, data):
    _, path, fmu, _ = trained
    assert validate_fmu(str(fmu)) == []
    ds = data[0]
    model = load_model(path).double()
    u, y = np.concatenate(ds.test.u + ds.valid.u), ds.test.y[0]
    with FmuSimulator(fmu, ds.input_names, ds.output_names, ds.Ts) as sim:
        got = sim.simulate(u, y[0])
    want = model.simulate(u, y[0])
    assert np.ptp(want) > 0.01 and _relative(got, want) < 1e-10
    spec = casadi_model(model).spec  # what the FMU declares: the node's own name, its offsets in the data's units
    assert spec.source["arch"] == "node"
    assert [(v.name, v.unit) for v in spec.parameters] == [("y1_mean", "m"), ("y1_std", "m")]


def test_model_exchange_with_cvode_follows_co_simulation(trained, data):
    ds, fmu = data[0], trained[2]
    runs = model_exchange_and_co_simulation(fmu, ds, ds.test.u[0], ds.test.y[0][0])
    assert np.ptp(runs["CoSimulation"]) > 0.01  # the run moves
    # CVode integrates the node's ODE at its own steps; co-simulation is one RK4 step per 10 ms sample
    assert _relative(runs["ModelExchange"], runs["CoSimulation"]) < 1e-5


def test_its_directional_derivatives_are_finite_differences(trained):
    me = MeInstance(trained[2], {"pos_start": 0.05})
    me.set({"F": 2.0})
    x = me.states_now() + np.array([0.3, -0.5, 0.2])
    me.set_states(x)
    unknowns, knowns = [f"der({s})" for s in me.states] + ["pos"], [*me.states, "F"]
    jacobian = me.jacobian(unknowns, knowns)
    fd = me.finite_differences(unknowns, {"F": 2.0}, floor=1e-3)
    np.testing.assert_array_less(np.abs(jacobian - fd) / np.abs(jacobian).max(axis=1, keepdims=True), 1e-6)
    assert np.count_nonzero(jacobian[:3]) >= 9  # the network couples every state and the input
    me.fmu.terminate()
    me.fmu.freeInstance()


@pytest.mark.parametrize("bad, says", [(["--states", "0"], "--states must be a whole number >= 1"),
                                        (["--physics", "slider"], "--physics only apply to --arch hybrid")])
def test_bad_options_are_one_line_status_2_and_no_file(bad, says, data, tmp_path, capsys):
    out = tmp_path / "bad.pt"
    assert main(["train", "--data", str(data[1]), "--arch", "node", *bad, "--epochs", "1", "-o", str(out)]) == 2
    assert not out.exists() and not list(tmp_path.iterdir())
    err = capsys.readouterr().err
    assert says in err and len(err.strip().splitlines()) == 1


def test_a_search_tries_no_feedback_noise_on_it():
    from nnfmu.study.time_space import axes
    from nnfmu.training import TrainConfig

    space = axes(NodeConfig(n_u=1, n_y=1), TrainConfig(), {"arch": "node"}, longest=400)
    assert space["arch"] == ("node",) and space["feedback_noise"] == (0.0,)  # the node refuses feedback noise


def test_its_options_are_listed_under_its_name(capsys):
    with pytest.raises(SystemExit):
        main(["train", "--help"])
    text = " ".join(capsys.readouterr().out.split())
    assert "--arch node: a neural ODE with no physics" in text and "--states N" in text and "--time-scale" in text
