"""Linear baseline: subspace identification, order choice, refinement, the init rules, export and storage."""

from __future__ import annotations

import json

import numpy as np
import pytest

from nnfmu.data import Channel, from_arrays
from nnfmu.errors import (
    CheckpointError,
    ConfigError,
    DataError,
    DataFileError,
    ShapeError,
    UnknownOptionError,
)
from nnfmu.linear import EarlyStop, LinearConfig, StateSpace, identify_linear, load_linear, refine

N_X, N_U, N_Y = 4, 2, 2
OUT_SCALE, OUT_OFFSET = np.array([10.0, 0.01]), np.array([5.0, -2e-3])  # outputs of very different size
IN_SCALE, IN_OFFSET = np.array([3.0, 500.0]), np.array([1.0, 1e3])


def true_system(seed: int = 0, radius: float = 0.9) -> StateSpace:
    """A random stable system in physical units (outputs and inputs of very different magnitudes)."""
    rng = np.random.default_rng(seed)
    A = rng.normal(size=(N_X, N_X))
    A *= radius / np.max(np.abs(np.linalg.eigvals(A)))
    B = rng.normal(size=(N_X, N_U)) / IN_SCALE
    C = rng.normal(size=(N_Y, N_X)) * OUT_SCALE[:, None]
    return StateSpace(A, B, np.zeros(N_X), C, OUT_OFFSET)


def run(sys: StateSpace, u: np.ndarray, x0: np.ndarray | None = None) -> np.ndarray:
    """Outputs (N, n_y); from rest for the constant input u[0] unless x0 is given."""
    x = np.linalg.solve(np.eye(N_X) - sys.A, sys.B @ u[0]) if x0 is None else x0
    y = np.empty((len(u), N_Y))
    for k, uk in enumerate(u):
        y[k] = sys.C @ x + sys.d
        x = sys.A @ x + sys.B @ uk
    return y


def inputs(rng, lengths) -> list[np.ndarray]:
    return [IN_OFFSET + IN_SCALE * rng.normal(size=(n, N_U)) for n in lengths]


def dataset(sys: StateSpace, seed: int = 1, noise: float = 0.0, lengths=(60, 90, 150, 41)):
    """Train (different lengths), valid and test trajectories that start at rest; optional output noise."""
    rng = np.random.default_rng(seed)
    splits = {}
    for name, lens in (("train", lengths), ("valid", (100, 120)), ("test", (300,))):
        us = inputs(rng, lens)
        ys = [run(sys, u) + noise * OUT_SCALE * rng.normal(size=(len(u), N_Y)) for u in us]
        splits[name] = (us, ys)
    return from_arrays(Ts=0.5, u_train=splits["train"][0], y_train=splits["train"][1],
                       u_valid=splits["valid"][0], y_valid=splits["valid"][1],
                       u_test=splits["test"][0], y_test=splits["test"][1],
                       input_names=[Channel("F", "N"), Channel("V", "V")],
                       output_names=[Channel("pos", "m"), Channel("gap", "m")])


def markov(sys: StateSpace, n: int = 30) -> np.ndarray:
    """Impulse response ``C A^k B``, k = 0..n-1, shape (n, n_y, n_u)."""
    out, M = [], sys.B
    for _ in range(n):
        out.append(sys.C @ M)
        M = sys.A @ M
    return np.array(out)


@pytest.fixture(scope="module")
def exact_data():
    return dataset(true_system())


@pytest.fixture(scope="module")
def noisy_data():
    return dataset(true_system(), noise=0.02)


@pytest.mark.parametrize("init", ["estimate", "zero-offset"])
def test_recovers_markov_parameters_of_a_known_system(exact_data, init):
    model = identify_linear(exact_data, order=N_X, init=init, refine=False)
    truth = markov(true_system())
    got = markov(model.system)
    np.testing.assert_allclose(got, truth, rtol=0, atol=1e-9 * np.abs(truth).max())
    assert np.array_equal(model.D, np.zeros((N_Y, N_U)))  # the contract: no direct feedthrough
    test = exact_data.test
    np.testing.assert_allclose(model.simulate(test.u[0], test.y[0][0]), test.y[0], rtol=0, atol=1e-9 * 10)


def test_many_short_trajectories_are_never_joined():
    """Forty 12..20-sample pieces from random states: exact only if no Hankel column spans two pieces."""
    sys = true_system(seed=3)
    rng = np.random.default_rng(4)
    us = inputs(rng, rng.integers(12, 21, size=40))
    ys = [run(sys, u, x0=rng.normal(size=N_X) * 50) for u in us]
    ds = from_arrays(Ts=1.0, u_train=us, y_train=ys, u_test=us[:1], y_test=ys[:1])
    model = identify_linear(ds, order=N_X, horizon=3, refine=False)
    truth = markov(sys)
    np.testing.assert_allclose(markov(model.system), truth, rtol=0, atol=1e-8 * np.abs(truth).max())


@pytest.mark.parametrize("init", ["estimate", "zero-offset"])
def test_order_selection_finds_the_true_order(exact_data, init):
    model = identify_linear(exact_data, init=init, max_order=8, refine=False)
    assert model.n_x == N_X
    scores = {int(k): v for k, v in model.info["order_scores"].items()}
    assert scores[N_X] < 1e-8 and scores[N_X - 1] > 1e-3
    assert model.info["singular_values"][N_X] < 1e-10 * model.info["singular_values"][0]


def test_refinement_lowers_the_error_and_keeps_the_model_stable(noisy_data):
    plain = identify_linear(noisy_data, order=2, refine=False)
    refined = identify_linear(noisy_data, order=2, max_evaluations=60)
    report = refined.info["refinement"]
    assert report["accepted"] and report["cost_after"] < report["cost_before"]
    assert refined.info["nrmse_valid"] < plain.info["nrmse_valid"]
    assert refined.system.spectral_radius < 0.9999


def test_refinement_respects_the_spectral_radius_limit(noisy_data):
    """The true poles reach 0.9; with a limit of 0.6 no accepted A may reach it."""
    model = identify_linear(noisy_data, order=N_X, max_spectral_radius=0.6, max_evaluations=40)
    assert model.info["stabilised"]
    assert model.system.spectral_radius < 0.6
    assert "spectral-radius limit" in model.info["refinement"]["message"]  # the user learns why it stopped
    assert model.info["nrmse_valid"] <= model.info["nrmse_subspace"]


def test_refinement_that_hurts_validation_is_discarded(noisy_data):
    """Validation outputs made by the subspace model itself: any refinement can only be worse there."""
    subspace = identify_linear(noisy_data, order=3, refine=False, refit=False)
    valid = noisy_data.valid
    made = [subspace.simulate(u, y[0]) for u, y in zip(valid.u, valid.y)]
    rigged = noisy_data.replace(splits={**noisy_data.splits, "valid": type(valid)(valid.u, tuple(made))})
    model = identify_linear(rigged, order=3, max_evaluations=300, refit=False)  # the choice itself, before a refit
    report = model.info["refinement"]
    assert report["cost_after"] < report["cost_before"]  # it did fit the training data better ...
    assert report["nrmse_after"] > model.info["nrmse_subspace"] and not report["accepted"]  # ... but not valid
    assert model.info["nrmse_valid"] == model.info["nrmse_subspace"] < 1e-12
    np.testing.assert_array_equal(model.system.A, subspace.system.A)
    assert report["best_evaluation"] == 0 and "no evaluation scored better than the start" in report["message"]


def test_identification_stops_the_refinement_on_the_validation_nrmse(noisy_data, monkeypatch):
    """identify_linear scores the validation free-run NRMSE every max_evaluations // 100 evaluations and
    stops after refine_patience checks without a better one (the tanks of docs/tutorial.md: 100
    evaluations instead of 1000)."""
    import nnfmu.linear.identify as identify

    seen, real_refine = [], identify.refine

    def spy(start, *args, **kwargs):
        seen.append((start, kwargs["early_stop"]))
        return real_refine(start, *args, **kwargs)

    monkeypatch.setattr(identify, "refine", spy)
    model = identify_linear(noisy_data, order=2, max_evaluations=300, refine_patience=4, refit=False)
    start, stop = seen[0]
    assert (stop.every, stop.patience) == (3, 4)
    assert stop.score(start) == model.info["nrmse_subspace"]  # the score is the validation free-run NRMSE
    assert model.info["nrmse_valid"] == model.info["refinement"]["nrmse_after"] <= model.info["nrmse_subspace"]
    identify_linear(noisy_data, order=2, max_evaluations=300, refine_patience=None, refit=False)
    assert seen[1][1] is None  # None: no early stop, the run goes to convergence or the limit
    with pytest.raises(ConfigError, match="refine_patience must be a positive integer"):
        LinearConfig(refine_patience=0)


def _perturbed_problem(seed: int = 8):
    """Normalised trajectories of a known system and a start 2 % off it."""
    rng = np.random.default_rng(seed)
    sys = StateSpace(true_system().A, rng.normal(size=(N_X, N_U)), np.zeros(N_X), rng.normal(size=(N_Y, N_X)),
                     np.zeros(N_Y))
    us = [rng.normal(size=(n, N_U)) for n in (80, 120)]
    ys = [run(sys, u, x0=np.zeros(N_X)) for u in us]
    return sys.replace(A=sys.A + 0.02 * rng.normal(size=(N_X, N_X)), B=sys.B * 1.05), us, ys


@pytest.mark.parametrize("method", ["quasi-newton", "gauss-newton"])
def test_early_stop_ends_the_refinement_and_returns_the_best_scored_system(method):
    start, us, ys = _perturbed_problem()
    flat = EarlyStop(lambda system: 1.0, every=2, patience=3)  # a validation score that never improves
    result = refine(start, us, ys, init="zero-offset", max_radius=0.9999, max_evaluations=500, method=method,
                    early_stop=flat)
    assert result.evaluations == 6 and result.best_evaluation == 0 and result.system is start
    assert result.score_before == result.score_after == 1.0 and result.cost_after == result.cost_before
    scored = []

    def training_error(system):  # improves with every step: the refinement runs to convergence as without
        scored.append(system)
        return refine(system, us, ys, init="zero-offset", max_radius=0.9999, max_evaluations=1).cost_before

    result = refine(start, us, ys, init="zero-offset", max_radius=0.9999, max_evaluations=500, method=method,
                    early_stop=EarlyStop(training_error, every=2, patience=3))
    assert result.cost_after < 1e-10 * result.cost_before and 0 < result.best_evaluation <= result.evaluations < 500
    assert result.score_after == pytest.approx(result.cost_after, rel=1e-6)
    assert len(scored) < result.evaluations  # scored every second evaluation at most, not at every one
    with pytest.raises(ConfigError, match="EarlyStop.every must be a positive integer"):
        EarlyStop(lambda system: 1.0, every=0)


@pytest.mark.parametrize("x0", ["rule", "fit"])
def test_refine_converges_back_to_the_true_system(x0):
    """From a perturbed start, output-error refinement recovers a system (normalised units)."""
    rng = np.random.default_rng(8)
    sys = StateSpace(*(m for m in (true_system().A, rng.normal(size=(N_X, N_U)), np.zeros(N_X),
                                   rng.normal(size=(N_Y, N_X)), np.zeros(N_Y))))
    us = [rng.normal(size=(n, N_U)) for n in (80, 120)]
    starts = [rng.normal(size=N_X) if x0 == "fit" else np.zeros(N_X) for _ in us]
    ys = [run(sys.replace(d=np.zeros(N_Y)), u, x0=s) for u, s in zip(us, starts)]
    start = sys.replace(A=sys.A + 0.02 * rng.normal(size=(N_X, N_X)), B=sys.B * 1.05)
    result = refine(start, us, ys, init="zero-offset", x0=x0, max_radius=0.9999, max_evaluations=60)
    assert result.cost_after < 1e-12 * result.cost_before
    np.testing.assert_allclose(markov(result.system), markov(sys), atol=1e-6)


@pytest.mark.parametrize("init", ["estimate", "zero-offset"])
def test_casadi_model_matches_numpy_simulation(noisy_data, init):
    model = identify_linear(noisy_data, order=3, init=init, max_evaluations=20)
    cm = model.casadi_model()
    assert cm.spec.name == "linear" and cm.spec.Ts == noisy_data.Ts
    assert [(v.name, v.unit) for v in cm.spec.inputs] == [("F", "N"), ("V", "V")]
    assert [(v.name, v.unit) for v in cm.spec.outputs] == [("pos", "m"), ("gap", "m")]
    u, y = noisy_data.test.u[0], noisy_data.test.y[0]
    want = model.simulate(u, y[0])
    np.testing.assert_allclose(cm.simulate(u, y[0]), want, rtol=1e-12, atol=1e-12 * np.abs(want).max())


def test_estimate_rule_starts_at_equilibrium_and_reproduces_y0(exact_data):
    model = identify_linear(exact_data, order=N_X, refine=False)
    u0 = np.array([2.0, 900.0])
    y_rest = run(true_system(), np.tile(u0, (5, 1)))[0]  # the output at rest under u0
    x0 = model.initial_state(y_rest, u0)
    sys = model.system
    np.testing.assert_allclose(sys.C @ x0 + sys.d, y_rest, rtol=1e-10)
    held = model.simulate(np.tile(u0, (50, 1)), y_rest)
    np.testing.assert_allclose(held, np.tile(y_rest, (50, 1)), rtol=1e-9)


def test_zero_offset_rule_carries_u0_and_y0(exact_data):
    model = identify_linear(exact_data, order=N_X, init="zero-offset", refine=False)
    cm = model.casadi_model()
    u0, y0 = np.array([1.5, -20.0]), np.array([3.0, 0.02])
    assert cm.n_x == N_X + N_U + N_Y
    np.testing.assert_array_equal(np.asarray(cm.init(y0, u0)).ravel(), np.concatenate([np.zeros(N_X), u0, y0]))
    u = exact_data.test.u[0][:80]
    base = model.simulate(u, y0)
    shifted = model.simulate(u + [4.0, 300.0], y0 + [1.0, 0.5])  # offsets are relative to the start
    np.testing.assert_allclose(shifted, base + [1.0, 0.5], rtol=1e-12, atol=1e-9)
    np.testing.assert_allclose(model.simulate(np.tile(u0, (30, 1)), y0), np.tile(y0, (30, 1)), rtol=1e-14)


def test_save_and_load_round_trip(noisy_data, tmp_path):
    model = identify_linear(noisy_data, order=3, max_evaluations=10)
    path = model.save(tmp_path / "linear.json")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["linear.json"]  # no temporary file left
    stored = json.loads(path.read_text())
    assert stored["format"] == "nnfmu-linear" and np.array_equal(stored["D"], np.zeros((N_Y, N_U)))
    back = load_linear(path)
    for name in ("A", "B", "b", "C", "d"):
        np.testing.assert_array_equal(getattr(back.system, name), getattr(model.system, name))
    assert back.init == model.init and back.inputs == model.inputs and back.info == model.info
    u, y = noisy_data.test.u[0], noisy_data.test.y[0]
    np.testing.assert_array_equal(back.simulate(u, y[0]), model.simulate(u, y[0]))


def test_load_errors(tmp_path):
    with pytest.raises(DataFileError, match="not found"):
        load_linear(tmp_path / "missing.json")
    (tmp_path / "bad.json").write_text("{not json")
    with pytest.raises(CheckpointError, match="not valid JSON"):
        load_linear(tmp_path / "bad.json")
    (tmp_path / "other.json").write_text(json.dumps({"format": "something-else"}))
    with pytest.raises(CheckpointError, match="not an nnfmu linear model"):
        load_linear(tmp_path / "other.json")


def test_integrator_is_stabilised():
    """A pure integrator (pole at 1) gives an A whose spectral radius is pulled inside the limit."""
    rng = np.random.default_rng(6)
    us = [rng.normal(size=(200, 1)) for _ in range(3)]
    ys = [np.concatenate([[[0.0]], np.cumsum(u[:-1], axis=0)]) for u in us]
    ds = from_arrays(Ts=0.1, u_train=us, y_train=ys, u_test=us[:1], y_test=ys[:1])
    model = identify_linear(ds, order=1, max_evaluations=20)
    assert model.info["stabilised"] and model.system.spectral_radius < 0.9999


def test_order_larger_than_the_data_allow(exact_data):
    short = dataset(true_system(), lengths=(20, 25))
    with pytest.raises(ShapeError, match="choose a smaller order"):
        identify_linear(short, order=30)
    with pytest.raises(ShapeError, match="exceeds what the data support"):
        identify_linear(exact_data, order=6, refine=False)


def test_identification_runs_on_the_configured_blas_threads(noisy_data, monkeypatch):
    """The BLAS thread count changes the refinement's end point (robot: 0.8514 on one thread, 0.8528 on
    two), so the baseline must not inherit it from the machine: inside, BLAS runs on ``threads``."""
    import nnfmu.linear.identify as identify
    from threadpoolctl import threadpool_info, threadpool_limits

    def blas_threads():
        return {pool["num_threads"] for pool in threadpool_info() if pool["user_api"] == "blas"}

    seen = []
    real_refine = identify.refine

    def spy(*args, **kwargs):
        seen.append(blas_threads())
        return real_refine(*args, **kwargs)

    monkeypatch.setattr(identify, "refine", spy)
    with threadpool_limits(limits=2, user_api="blas"):
        outer = blas_threads()
        one = identify_linear(noisy_data, order=2, max_evaluations=20, refit=False)
        two = identify_linear(noisy_data, order=2, max_evaluations=20, threads=2, refit=False)
        after = blas_threads()
    assert seen[0] == {1}
    assert seen[1] == outer and after == outer  # threads=2 runs on the caller's two; the caller's setting is restored
    assert one.info["config"]["threads"] == 1 and two.info["config"]["threads"] == 2


def test_option_errors(exact_data):
    with pytest.raises(UnknownOptionError, match="valid options are: .*max_order"):
        identify_linear(exact_data, ordr=3)
    with pytest.raises(ConfigError, match="init must be one of estimate, zero-offset"):
        LinearConfig(init="zero")
    with pytest.raises(ConfigError, match="positive integer"):
        LinearConfig(order=0)
    with pytest.raises(ConfigError, match="threads must be a positive integer"):
        LinearConfig(threads=0)
    with pytest.raises(ConfigError, match="not both"):
        identify_linear(exact_data, LinearConfig(order=2), order=3)
    unstable = true_system(radius=1.1)
    with pytest.raises(ConfigError, match="must start from a stable system.*stabilise"):
        refine(unstable, [np.zeros((10, N_U))], [np.zeros((10, N_Y))], init="estimate", max_radius=0.9999,
               max_evaluations=5)


def test_dataset_with_nan_is_refused():
    u = np.ones((50, 1))
    y = np.ones((50, 1))
    y[7] = np.nan
    with pytest.raises(DataError, match="non-finite"):
        identify_linear(from_arrays(Ts=1.0, u_train=u, y_train=y, u_test=u, y_test=u))
