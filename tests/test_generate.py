"""Generated datasets (valve and arm) and the ``nnfmu generate`` command."""

from __future__ import annotations

import json
import math

import casadi as ca
import numpy as np
import pytest

from nnfmu.cli import main
from nnfmu.data import load_dataset
from nnfmu.data.loaders import ROBOT_INPUTS, ROBOT_OUTPUTS
from nnfmu.errors import ConfigError
from nnfmu.metrics import nrmse
from nnfmu.physics import arm_system, generate_dataset, valve_system
from nnfmu.physics.arm import ARM_Q_LIMITS_DEG, Q_DH_OFFSET


@pytest.fixture(scope="module")
def arm_small_dir(tmp_path_factory):
    """``nnfmu generate arm --size small`` written by the CLI; returns the folder."""
    out = tmp_path_factory.mktemp("gen") / "arm_small"
    assert main(["generate", "arm", "--size", "small", "--out", str(out), "--quiet"]) == 0
    return out


@pytest.fixture(scope="module")
def arm_small(arm_small_dir):
    return load_dataset(arm_small_dir)


def test_valve_dataset_has_the_promised_shape_names_and_units(valve_small):
    ds = valve_small
    assert ds.Ts == 40e-6
    assert [(c.name, c.unit) for c in ds.inputs] == [("u1", "V"), ("u2", "V")]
    assert [(c.name, c.unit) for c in ds.outputs] == [("s", "m"), ("p", "Pa")]
    assert (ds.train.n_traj, set(ds.train.lengths)) == (40, {300})
    assert (ds.test.n_traj, set(ds.test.lengths)) == (3, {1500})
    source = json.loads(json.dumps(ds.source))  # JSON-serialisable
    assert source["generator"] == "nnfmu.physics.generate_valve" and source["seed"] == 0
    assert source["size"] == "small" and source["params"]["k_s"] == 25e3


def test_valve_values_are_finite_and_physically_plausible(valve_small):
    for tr in (valve_small.train, valve_small.test):
        u, y = np.concatenate(tr.u), np.concatenate(tr.y)
        assert np.isfinite(u).all() and np.isfinite(y).all()
        assert u.min() >= 0.0 and u.max() <= 250.0
        assert max(np.abs(np.diff(ui, axis=0)).max() for ui in tr.u) <= 5e5 * 40e-6 + 1e-9  # slew limit
        assert -10e-6 < y[:, 0].min() and y[:, 0].max() < 1.01e-3          # plunger inside its stroke
        assert 1.013e5 - 1e3 < y[:, 1].min() and y[:, 1].max() < 7.0e5 + 1e3  # between exhaust and supply


def test_valve_data_contain_plunger_motion_and_end_stop_contacts(valve_small):
    s = np.concatenate(valve_small.train.y)[:, 0]
    assert np.mean(s < 0.02e-3) > 0.02 and np.mean(s > 0.98e-3) > 0.02   # closed and fully open
    assert np.mean((s > 0.1e-3) & (s < 0.9e-3)) > 0.1                    # and in between
    for y in valve_small.test.y:                                          # NRMSE needs non-constant outputs
        assert y[:, 0].std() > 2e-5 and y[:, 1].std() > 1e4
    y0 = np.array([y[0] for y in valve_small.train.y])
    assert y0[:, 1].std() > 0.5e5  # trajectories start from varied states (random warm-up)


def test_valve_data_are_what_the_physics_model_simulates(valve_small):
    """The RK4 model started from the measured y0 reproduces the test outputs (init from y0 only)."""
    model = valve_system().model()
    predictions = [model.simulate(u, y[0]) for u, y in zip(valve_small.test.u, valve_small.test.y)]
    assert nrmse(list(valve_small.test.y), predictions).mean < 0.01


def test_valve_generation_is_reproducible(valve_small):
    again = generate_dataset("valve", size="small", seed=0)
    other = generate_dataset("valve", size="small", seed=1)
    assert all(np.array_equal(a, b) for a, b in zip(again.train.y, valve_small.train.y))
    assert all(np.array_equal(a, b) for a, b in zip(again.test.u, valve_small.test.u))
    assert not np.allclose(other.test.u[0], valve_small.test.u[0])


def test_valve_round_trips_through_the_cli(valve_small, tmp_path, capsys):
    out = tmp_path / "valve"
    assert main(["generate", "valve", "--size", "small", "--seed", "0", "--out", str(out), "--quiet"]) == 0
    assert f"wrote {out}" in capsys.readouterr().out
    loaded = load_dataset(out)
    assert loaded.Ts == valve_small.Ts and loaded.output_names == ["s", "p"]
    for name in ("train", "test"):
        for a, b in zip(loaded.split(name).y, valve_small.split(name).y):
            assert np.array_equal(a, b)
    assert loaded.source["seed"] == 0


def test_arm_dataset_has_the_benchmark_channels(arm_small):
    ds = arm_small
    assert ds.Ts == 0.1
    assert [(c.name, c.unit) for c in ds.inputs] == [(c.name, c.unit) for c in ROBOT_INPUTS]
    assert [(c.name, c.unit) for c in ds.outputs] == [(c.name, c.unit) for c in ROBOT_OUTPUTS]
    assert (ds.train.n_traj, set(ds.train.lengths)) == (2, {300})
    assert (ds.test.n_traj, set(ds.test.lengths)) == (1, {300})  # one continuous record
    assert ds.source["generator"] == "nnfmu.physics.generate_arm"


def test_arm_values_are_finite_and_inside_the_joint_limits(arm_small):
    limits = np.array(ARM_Q_LIMITS_DEG)
    for tr in (arm_small.train, arm_small.test):
        u, y = np.concatenate(tr.u), np.concatenate(tr.y)
        assert np.isfinite(u).all() and np.isfinite(y).all()
        q_dh = y + np.degrees(Q_DH_OFFSET)
        assert (q_dh > limits[:, 0]).all() and (q_dh < limits[:, 1]).all()
        assert np.abs(u).max() < 40.0                         # motor torques of the real data's order
        assert (np.ptp(y, axis=0) > 2.0).all()                # every joint moves
        speed = max(np.abs(np.diff(yi, axis=0)).max() for yi in tr.y) / 0.1
        assert speed < 140.0                                  # deg/s: below twice the reference speed limits


def test_arm_record_starts_at_rest_and_its_torques_produce_its_angles(arm_small):
    """The exact model driven by the recorded (period-mean) torques follows the record for 2 s."""
    u, y = arm_small.test.u[0], arm_small.test.y[0]
    assert np.abs(y[1] - y[0]).max() < 0.05  # blended in from rest
    system = arm_system(f_b_cap=None)
    x, tau = ca.SX.sym("x", 12), ca.SX.sym("u", 6)
    p = ca.SX.sym("p", len(system.parameters))
    step = ca.integrator("F", "cvodes", {"x": x, "p": ca.vertcat(tau, p), "ode": system.ode(x, tau, p)},
                         0.0, [0.1], {"abstol": 1e-10, "reltol": 1e-10})
    state = np.concatenate([np.radians(y[0]), np.zeros(6)])
    for k in range(20):
        state = np.asarray(step(x0=state, p=np.concatenate([u[k], system.parameter_values()]))["xf"]).ravel()
        assert np.abs(np.degrees(state[:6]) - y[k + 1]).max() < 0.3  # measured 0.12 deg after 2 s


@pytest.mark.parametrize("argv, message", [
    (["generate", "pump", "--out", "D"], "unknown physics model 'pump'; choose one of arm, slider, valve"),
    (["generate", "valve", "--size", "huge", "--out", "D"],
     "unknown size 'huge' for the valve; valid sizes are paper, small"),
    (["generate", "arm", "--size", "paper", "--out", "D"], "valid sizes are benchmark, small"),
    (["generate", "valve", "--size", "small", "--seed", "-3", "--out", "D"], "--seed must be a whole number >= 0"),
    (["generate", "valve", "--size", "small", "--out", "blocker/D"], "is not a writable folder"),
    (["generate", "valve", "--size", "small", "--out", "existing"],
     "already exists; choose another folder or pass --force"),
])
def test_bad_generate_requests_give_one_line_and_status_2(argv, message, tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "blocker").write_text("a file where a folder is needed")
    (tmp_path / "existing").mkdir()
    before = sorted(p.name for p in tmp_path.iterdir())
    assert _exit_status(argv) == 2
    err = capsys.readouterr().err
    assert message in err and err.count("\n") == 1 and err.startswith("nnfmu generate: error: ")
    assert sorted(p.name for p in tmp_path.iterdir()) == before  # nothing half-written
    assert list((tmp_path / "existing").iterdir()) == []


def _exit_status(argv) -> int:
    """``main``'s return value, or the status of argparse's own exit (usage errors)."""
    try:
        return main(argv)
    except SystemExit as exc:
        return exc.code


def test_generate_dataset_rejects_unknown_systems():
    with pytest.raises(ConfigError, match="unknown physics model 'pump'; choose one of arm, slider, valve"):
        generate_dataset("pump")
    with pytest.raises(ConfigError, match="seed must be a non-negative integer"):
        generate_dataset("valve", seed=1.5)


def test_arm_benchmark_size_is_about_the_real_benchmark():
    from nnfmu.physics.generate_arm import ARM_SIZES

    cfg = ARM_SIZES["benchmark"]
    per_traj = round(cfg.segment_time / 0.1)
    assert 38000 <= cfg.n_train * cfg.train_segments * per_traj <= 42000
    assert cfg.n_test == 1 and 3400 <= cfg.test_segments * per_traj <= 3800
    assert math.isclose(cfg.period, 10.0) and cfg.n_harmonics == 5


def test_interrupted_arm_generation_resumes_from_finished_trajectories(tmp_path, monkeypatch):
    import nnfmu.physics.generate_arm as gen

    real = gen._trajectory
    calls = []

    def first_then_stop(*args, **kwargs):
        if calls:
            raise KeyboardInterrupt
        calls.append(1)
        return real(*args, **kwargs)

    partial = tmp_path / ".arm.partial"
    monkeypatch.setattr(gen, "_trajectory", first_then_stop)
    with pytest.raises(KeyboardInterrupt):
        gen.generate_arm(size="small", seed=3, partial_dir=partial)
    assert (partial / "0_0.npz").exists()

    simulated = []
    monkeypatch.setattr(gen, "_trajectory", lambda *a, **k: simulated.append(1) or real(*a, **k))
    resumed = gen.generate_arm(size="small", seed=3, partial_dir=partial)
    assert len(simulated) == resumed.train.n_traj + resumed.test.n_traj - 1  # the finished one was reused
    fresh = gen.generate_arm(size="small", seed=3)
    for a, b in zip(resumed.train.u + resumed.test.y, fresh.train.u + fresh.test.y):
        np.testing.assert_array_equal(a, b)
    # another request (seed) must not reuse the stored trajectories
    other = gen.generate_arm(size="small", seed=4, partial_dir=partial)
    assert not np.array_equal(other.train.u[0], resumed.train.u[0])
