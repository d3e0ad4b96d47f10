"""Grey-box identification: the free parameters of a physics model from measured data, by simulation error.

:func:`fit_greybox` minimises the output error of the model's RK4 free run over windows of the training
records, each window starting from its own estimated initial state (:mod:`nnfmu.greybox.problem`), within
the parameters' bounds, from one or more starting points (:mod:`nnfmu.greybox.setup`), with SciPy's
trust-region least squares on CasADi's exact Jacobian (:mod:`nnfmu.greybox.solvers`, which says why).

Standard errors are Gauss-Newton's: ``sigma^2 (J^T J)^-1`` at the optimum over every unknown (the parameters
and the windows' initial states), of which the parameters' block is taken (by the Schur complement, the
states' blocks being one small block per window), with ``sigma^2 = |r|^2 / (n_r - n_z)``. They assume
white measurement noise and a model of the right structure; on a mis-specified model they are too small.

The fitted model is scored as every model of the toolkit is: the free run from each record's measured
first output (``init_state``), NRMSE, RMSE and fit % by :func:`nnfmu.metrics.nrmse`, per split.
"""

from __future__ import annotations

import dataclasses
import time
import warnings
from dataclasses import dataclass, field

import numpy as np

from nnfmu.errors import ConfigError
from nnfmu.greybox.identifiability import covariance, identifiability_report, parameter_information
from nnfmu.greybox.problem import Windows, build_problem, cut_windows, theta_scales
from nnfmu.greybox.setup import Unknowns, check_dataset, choose_unknowns, spread_starts
from nnfmu.greybox.solvers import SOLVERS, solve
from nnfmu.greybox.window import compile_worthwhile
from nnfmu.physics.base import PhysicsSystem
from nnfmu.physics.compiled import compile_function
from nnfmu.physics.initial_state import estimating_model
from nnfmu.progress import tqdm
from nnfmu.protocols import Protocol

__all__ = ["FitConfig", "GreyboxFit", "fit_greybox", "gauss_newton", "standard_errors", "score_system",
           "COMPILE_CHOICES"]

COMPILE_CHOICES = ("auto", "on", "off")


@dataclass(frozen=True, kw_only=True)
class FitConfig:
    """How to fit.

    Attributes
    ----------
    free, fixed : tuple of str
        Parameters to estimate (None: the model's ``free_parameters``, else all), and ones to hold.
    bounds : dict name -> (lo, hi)
        Overrides each parameter's ``min`` / ``max`` (None: unbounded on that side), in its unit.
    start : dict name -> value
        Overrides each parameter's nominal ``start``.
    window : int
        Samples per window (at most the shortest training record), >= 2.
    starts : int
        Starting points: the given start, then ``starts - 1`` random ones (:func:`spread_starts`).
    seed : int
        Seeds the random starting points.
    solver : str
        ``"trf"`` (default) or ``"ipopt"`` (:mod:`nnfmu.greybox.solvers`).
    max_evaluations : int, optional
        Residual evaluations (trf) or iterations (IPOPT) per start. None (default): until the solver converges,
        within :data:`~nnfmu.greybox.solvers.DEFAULT_MAX_EVALUATIONS`; the report says why it stopped.
    n_sub : int, optional
        RK4 sub-steps per sample (default the model's own).
    max_windows : int, optional
        Fit on at most this many windows, spread evenly over the training split (default: every window).
        For a model whose iteration over the whole split takes too long (the arm on the robot).
    compile : str
        ``"auto"`` (default): the windows' free runs and sensitivities run as compiled C when the ODE's
        instructions times the sub-steps reach :data:`~nnfmu.greybox.window.COMPILE_MIN_INSTRUCTIONS`;
        ``"on"`` or ``"off"`` decide. Same values either way.
    init_window : int
        1 (default): every split is scored by the free run from each record's first sample (the init rule).
        ``N > 1``: by the free run after an init window of ``N`` samples, from the state that the FMU's
        estimator (:mod:`nnfmu.physics.initial_state`) computes from them, with the errors divided by the
        training split's standard deviation per output, as in the fit; the fit file keeps ``N``, so
        ``nnfmu export`` builds that FMU, and ``nnfmu evaluate --init-window N`` gives the same scores.
    """

    free: tuple[str, ...] | None = None
    fixed: tuple[str, ...] = ()
    bounds: dict = field(default_factory=dict)
    start: dict = field(default_factory=dict)
    window: int = 200
    starts: int = 1
    seed: int = 0
    solver: str = "trf"
    max_evaluations: int | None = None
    n_sub: int | None = None
    max_windows: int | None = None
    compile: str = "auto"
    init_window: int = 1

    def __post_init__(self) -> None:
        if self.solver not in SOLVERS:
            raise ConfigError(f"unknown solver {self.solver!r}; choose one of {', '.join(SOLVERS)}")
        if self.compile not in COMPILE_CHOICES:
            raise ConfigError(f"compile must be one of {', '.join(COMPILE_CHOICES)}, got {self.compile!r}")
        for name, low in (("window", 2), ("starts", 1), ("max_evaluations", 1), ("n_sub", 1), ("max_windows", 1),
                          ("init_window", 1)):
            value = getattr(self, name)
            if value is not None and (isinstance(value, bool) or int(value) != value or value < low):
                raise ConfigError(f"{name} must be a whole number >= {low}, got {value!r}")


@dataclass(frozen=True)
class GreyboxFit:
    """The fitted model (each free parameter's ``start`` is its estimate) and the report (JSON-safe dict)."""

    system: PhysicsSystem
    report: dict


def gauss_newton(problem, z: np.ndarray, cost: float) -> tuple[np.ndarray, float]:
    """``(information, sigma2)``: the free parameters' information in the scaled unknowns (n_f, n_f; the
    windows' initial states eliminated) and the residuals' variance ``2 cost / (n_r - n_z)`` (NaN if n_r <= n_z)."""
    dt, dx = problem.blocks(z)
    n_r = dt.shape[0] * dt.shape[1]
    sigma2 = 2.0 * cost / (n_r - problem.n_z) if n_r > problem.n_z else np.nan
    return parameter_information(dt, dx), sigma2


def standard_errors(problem, z: np.ndarray, cost: float) -> np.ndarray:
    """Gauss-Newton standard errors of the free parameters (n_f,), in their units (module docstring); Inf for
    a parameter in a direction the data do not see at all (:func:`nnfmu.greybox.identifiability.covariance`)."""
    return _errors(*gauss_newton(problem, z, cost), problem.theta_scale)


def _errors(information: np.ndarray, sigma2: float, theta_scale: np.ndarray) -> np.ndarray:
    if not np.isfinite(sigma2):
        return np.full(len(theta_scale), np.nan)
    cov, null = covariance(information, sigma2)
    return np.where(null, np.inf, theta_scale * np.sqrt(np.clip(np.diag(cov), 0.0, None)))


def score_system(system: PhysicsSystem, dataset, *, n_sub: int | None = None, compile: bool = False,
                 init_window: int = 1, y_scale=None, splits=None) -> dict:
    """``{split: scores}``: the free run of every record from its first sample, NRMSE / RMSE / fit % per split
    (``splits``: the names to score, default every split of ``dataset``).

    ``compile``: the RK4 step runs as compiled C (same values; the arm's 36,300 training samples took 4 minutes
    in CasADi's virtual machine). ``init_window`` N > 1: the free run after the first N samples, from the
    state the FMU's estimator gives (``y_scale``: its output scales; :mod:`nnfmu.physics.initial_state`),
    scored from sample N on, as ``nnfmu evaluate --init-window N`` scores the FMU.
    """
    model = estimating_model(system, n_sub=n_sub, expose_parameters=False, init_window=init_window, y_scale=y_scale)
    if compile:
        model = dataclasses.replace(model, step=compile_function(model.step))
    protocol, out = Protocol(init_window=init_window), {}
    simulate = lambda u, y0, y_past, u_past: model.simulate(u, y0, y_past=y_past, u_past=u_past)  # noqa: E731
    for name, split in dataset.splits.items():
        if splits is not None and name not in splits:
            continue
        predictions = [protocol.predict(simulate, u, y, init_window - 1) for u, y in zip(split.u, split.y)]
        if not all(np.isfinite(p).all() for p in predictions):
            out[name] = {"nrmse": None, "note": "the free run diverged (NaN or Inf)"}
            continue
        scores = protocol.score(list(split.y), predictions).to_json(list(dataset.outputs))
        scores.pop("trajectories")
        out[name] = scores
    return out


def _initial_states(system: PhysicsSystem, windows, p: np.ndarray) -> np.ndarray:
    """Each window's state by the model's ``init_state`` from its first sample: (n_w, n_x)."""
    y0, u0 = windows.y[:, 0, :].T, windows.u[:, 0, :].T
    x0 = system.init_state.map(windows.n_w)(y0, u0, np.repeat(p[:, None], windows.n_w, axis=1))
    return np.asarray(x0).T


def _with_starts(system: PhysicsSystem, start: dict) -> PhysicsSystem:
    params = tuple(dataclasses.replace(v, start=float(start[v.name])) if v.name in start else v
                   for v in system.parameters)
    return dataclasses.replace(system, parameters=params)


def _fitted_system(system: PhysicsSystem, unknowns: Unknowns, theta: np.ndarray, dataset_source) -> PhysicsSystem:
    params = list(system.parameters)
    for i, value, lo, hi in zip(unknowns.index, theta, unknowns.lower, unknowns.upper):
        params[i] = dataclasses.replace(params[i], start=float(value), min=float(lo) if np.isfinite(lo) else None,
                                        max=float(hi) if np.isfinite(hi) else None)
    fitted = {n: float(v) for n, v in zip(unknowns.names, theta)}
    source = {**system.source, "greybox_fit": {"parameters": fitted, "data": dataset_source}}
    return dataclasses.replace(system, parameters=tuple(params), free_parameters=unknowns.names, source=source)


def _run_starts(system, problem, windows, unknowns, config, progress):
    points = spread_starts(unknowns, config.starts, np.random.default_rng(config.seed))
    lower = np.concatenate([unknowns.lower / problem.theta_scale, np.full(problem.n_z - problem.n_f, -np.inf)])
    upper = np.concatenate([unknowns.upper / problem.theta_scale, np.full(problem.n_z - problem.n_f, np.inf)])
    runs, best = [], None
    bar = tqdm(total=len(points), disable=not progress, unit="start", desc=f"fit {system.name}", dynamic_ncols=True)
    with bar:
        for k, theta in enumerate(points):
            p = _parameters_at(problem, theta)
            z0 = problem.pack(theta, _initial_states(system, windows, p))
            if not np.isfinite(problem.evaluate(z0)).all():
                if k == 0:
                    raise ConfigError(f"the free run of {system.name} at the start parameters gives NaN or Inf; "
                                      "check the model, its init_state and the start values (--start)")
                runs.append({"start": dict(zip(unknowns.names, map(float, theta))), "status": "skipped: NaN or Inf "
                             "at this start"})
                bar.update(1)
                continue
            report = lambda n, cost, best_cost: bar.set_postfix(evaluations=n, cost=f"{cost:.4g}",  # noqa: E731
                                                                best=f"{best_cost:.4g}")
            with warnings.catch_warnings(), np.errstate(all="ignore"):  # SciPy's overflows inside a step it rejects
                warnings.simplefilter("ignore", RuntimeWarning)
                outcome = solve(problem, z0, lower, upper, solver=config.solver,
                                max_evaluations=config.max_evaluations, report=report)
            runs.append({"start": dict(zip(unknowns.names, map(float, theta))), "cost": outcome.cost,
                         "evaluations": outcome.evaluations, "seconds": round(outcome.seconds, 3),
                         "status": outcome.status, "stopped": outcome.reason, "notes": outcome.notes,
                         "end": dict(zip(unknowns.names, map(float, problem.parameters(outcome.z)[unknowns.index])))})
            if best is None or outcome.cost < best.cost:
                best = outcome
            bar.update(1)
    return best, runs


def _parameters_at(problem, theta: np.ndarray) -> np.ndarray:
    """The full parameter vector with the free ones at ``theta`` (physical units)."""
    p = problem.p_fixed.copy()
    p[problem.free] = theta
    return p


def fit_greybox(system: PhysicsSystem, dataset, config: FitConfig | None = None, *,
                progress: bool = False, score_test: bool = False) -> GreyboxFit:
    """Estimate ``system``'s free parameters from ``dataset``'s training split (module docstring).

    Parameters
    ----------
    system : PhysicsSystem
        The model, e.g. ``nnfmu.physics.resolve_physics("slider")``.
    dataset : nnfmu.data.Dataset
        Inputs and outputs named and in units as the model's, at its sample time; ``train`` is fitted,
        ``valid`` (if present) only scored.
    config : FitConfig
    progress : bool
        A bar over the starting points, with the evaluations and the cost of the current one.
    score_test : bool
        Score the ``test`` split too (default False: a fit is judged on validation; the test split is for the
        model finally chosen, ``nnfmu fit --report-test``).

    Returns
    -------
    GreyboxFit
        ``.system``: the model with the estimates as its parameters' starts; ``.report``: values, standard
        errors, ``identifiability`` (:func:`nnfmu.greybox.identifiability_report`), why the solver
        stopped (``converged``, ``stopped``), scores per split, the starts tried and the seconds taken.
    """
    t0 = time.perf_counter()
    config = config or FitConfig()
    check_dataset(system, dataset)
    unknowns = choose_unknowns(system, free=config.free, fixed=config.fixed, bounds=config.bounds,
                               start=config.start)
    system = _with_starts(system, config.start)  # a start given for a fixed parameter is its value
    train = dataset.train
    length = int(min(config.window, train.lengths.min()))
    every_window = cut_windows(train.u, train.y, length)
    windows = _spread(every_window, config.max_windows)
    y_all = np.concatenate(train.y)
    y_std = np.maximum(y_all.std(axis=0), 1e-12 * np.maximum(1.0, np.abs(y_all.mean(axis=0))))
    p_start = system.parameter_values()
    scale = theta_scales(unknowns.start, unknowns.lower, unknowns.upper)
    n_sub = config.n_sub or system.n_sub
    compiled = config.compile == "on" or (config.compile == "auto" and compile_worthwhile(system, n_sub))
    problem = build_problem(system, windows, unknowns.index, p_start, scale, y_std, n_sub=n_sub, compile=compiled)
    best, runs = _run_starts(system, problem, windows, unknowns, config, progress)
    if best is None or best.z is None:
        raise ConfigError("every starting point gave NaN or Inf; give starts where the model's free run is finite")
    theta = problem.parameters(best.z)[unknowns.index]
    information, sigma2 = gauss_newton(problem, best.z, best.cost)  # one Jacobian: the arm's takes a minute
    errors = _errors(information, sigma2, problem.theta_scale)
    fitted = _fitted_system(system, unknowns, theta, dict(dataset.source))
    n_r = windows.n_w * length * len(system.outputs)
    parameters = {}
    for j, name in enumerate(unknowns.names):
        v = system.parameters[unknowns.index[j]]
        near = 1e-6 * problem.theta_scale[j]  # relative to the parameter's size: C_max is 6e-10 m3/(s.Pa)
        at_bound = bool(min(abs(theta[j] - unknowns.lower[j]), abs(theta[j] - unknowns.upper[j])) <= near)
        parameters[name] = {"value": float(theta[j]), "unit": v.unit, "std_error": float(errors[j]),
                            "start": float(unknowns.start[j]), "min": _finite(unknowns.lower[j]),
                            "max": _finite(unknowns.upper[j]), "at_bound": at_bound, "description": v.description}
    report = {"model": system.name, "solver": config.solver, "window": length, "windows": windows.n_w,
              "windows_in_split": every_window.n_w,
              "n_sub": n_sub, "compiled": compiled, "residuals": n_r, "unknowns": problem.n_z, "cost": best.cost,
              "residual_rms": float(np.sqrt(2.0 * best.cost / n_r)), "parameters": parameters,
              "fixed": {v.name: v.start for i, v in enumerate(system.parameters) if i not in set(unknowns.index)},
              "starts": runs, "notes": best.notes, "converged": best.converged, "stopped": best.reason,
              "identifiability": (identifiability_report(unknowns.names, theta, problem.theta_scale, information,
                                                         sigma2) if np.isfinite(sigma2) else None),
              "init_window": config.init_window, "output_scales": y_std.tolist(),
              "scores": score_system(fitted, dataset, n_sub=n_sub, compile=compiled, init_window=config.init_window,
                                     y_scale=y_std, splits=None if score_test else ("train", "valid"))}
    report["seconds"] = round(time.perf_counter() - t0, 3)
    return GreyboxFit(system=fitted, report=report)


def _spread(windows: Windows, most: int | None) -> Windows:
    """At most ``most`` of ``windows``, evenly spread over them (first and last kept); all when None."""
    if most is None or windows.n_w <= most:
        return windows
    pick = np.unique(np.linspace(0, windows.n_w - 1, most).round().astype(int))
    return Windows(windows.u[pick], windows.y[pick])


def _finite(x: float) -> float | None:
    return float(x) if np.isfinite(x) else None

