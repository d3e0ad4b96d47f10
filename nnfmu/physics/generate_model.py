"""Datasets from any physics model (a user's own): the toolkit's excitation signals within its input ranges.

Every record starts where the model's init rule puts it for the outputs' ``start`` values and the first
input, and follows a random excitation (holds, ramps, APRBS, multisines and chirps, :mod:`nnfmu.signals`)
inside each input's ``[min, max]``. The excitation's time scales follow the model's ``settle_time``
(``source["settle_time"]``, set by ``ModelBuilder(settle_time=...)``; default ``50 Ts``). Measurement
noise, when asked, is white and Gaussian, its standard deviation a fraction of each output's standard
deviation over the training split. The built-in valve, arm and slider keep their own generators
(:func:`nnfmu.physics.generate_dataset`).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from nnfmu.data import Channel, Dataset, Trajectories
from nnfmu.errors import ConfigError, SimulationError
from nnfmu.physics.base import PhysicsSystem
from nnfmu.physics.rk4 import rk4_function
from nnfmu.signals import ExcitationConfig, SignalLimits, excitation

__all__ = ["ModelDataConfig", "MODEL_SIZES", "model_excitation", "generate_model_dataset", "add_noise"]


@dataclass(frozen=True, kw_only=True)
class ModelDataConfig:
    """Numbers of trajectories and samples per split (validation and test records are ``test_steps`` long)."""

    n_train: int
    train_steps: int
    n_valid: int
    n_test: int
    test_steps: int


MODEL_SIZES = {
    "standard": ModelDataConfig(n_train=40, train_steps=1000, n_valid=4, n_test=4, test_steps=4000),
    "small": ModelDataConfig(n_train=16, train_steps=400, n_valid=2, n_test=2, test_steps=1600),
}


def model_excitation(system: PhysicsSystem) -> tuple[ExcitationConfig, tuple[SignalLimits, ...]]:
    """The excitation settings and per-input limits for ``system``, scaled to its settling time ``T``.

    Sections last ``T`` to ``4 T``, APRBS holds ``0.2 T`` to ``1.5 T``, the sine bands span ``0.05 / T``
    to ``1.5 / T`` Hz (at most a quarter of the Nyquist frequency), and an input crosses its whole range
    in no less than ``0.2 T``. Raises ConfigError for an input without a finite range.
    """
    if not system.inputs:
        raise ConfigError(f"{system.name} has no inputs; generate excites a model through its inputs, so declare "
                          f"at least one with input(..., min=, max=)")
    open_inputs = [v.name for v in system.inputs if v.min is None or v.max is None or v.min >= v.max]
    if open_inputs:
        raise ConfigError(f"{system.name}: input(s) {', '.join(open_inputs)} have no range to excite within; "
                          f"give min= and max= in the model's input(...)")
    T = float(system.source.get("settle_time", 50.0 * system.Ts))
    top = min(1.5 / T, 0.125 / system.Ts)
    band = (min(0.05 / T, 0.5 * top), top)
    config = ExcitationConfig(section_time=(T, 4.0 * T), aprbs_hold=(0.2 * T, 1.5 * T), multisine_band=band,
                              chirp_band=band, kinds=("hold", "ramp", "aprbs", "multisine", "chirp"),
                              weights=(0.6, 0.6, 1.5, 1.0, 0.8), extreme_fraction=0.1)
    limits = tuple(SignalLimits(u_min=v.min, u_max=v.max, rate_max=(v.max - v.min) / (0.2 * T))
                   for v in system.inputs)
    return config, limits


def _record(system: PhysicsSystem, step, u: np.ndarray) -> np.ndarray:
    """Outputs (N, n_y) of a free run under ``u`` (N, n_u): y[0] from the init rule, y[k + 1] after u[k]."""
    p = system.parameter_values()
    y_start = np.array([v.start for v in system.outputs], dtype=float)
    x0 = np.asarray(system.init_state(y_start, u[0], p), dtype=float).ravel()
    xs = np.asarray(step.mapaccum("sim", len(u) - 1)(x0, u[:-1].T, np.repeat(p[:, None], len(u) - 1, 1)))
    x = np.hstack([x0[:, None], xs])
    y = np.asarray(system.output.map(x.shape[1])(x, np.repeat(p[:, None], x.shape[1], 1))).T
    if not (np.isfinite(x).all() and np.isfinite(y).all()):
        raise SimulationError(f"{system.name}: the simulation produced NaN or Inf; check the ODE over the input "
                              f"ranges, or use more RK4 sub-steps (n_sub)")
    return y


def _split(system, step, config, limits, n_traj: int, n_steps: int, seed: int, split: int) -> Trajectories:
    us, ys = [], []
    for i in range(n_traj):
        u = excitation(n_steps, Ts=system.Ts, limits=limits, config=config,
                       seed=np.random.default_rng([seed, split, i]))
        us.append(u)
        ys.append(_record(system, step, u))
    return Trajectories(tuple(us), tuple(ys))


def generate_model_dataset(system: PhysicsSystem | str, *, size: str = "standard", seed: int = 0,
                           noise: float = 0.0) -> Dataset:
    """Simulate ``system`` at its nominal parameters into train, valid and test splits.

    Parameters
    ----------
    system : PhysicsSystem or str
        Any model with a finite ``[min, max]`` on every input, or a spec of one
        (:func:`nnfmu.physics.resolve_physics`: ``"path/to/file.py:NAME"`` runs that file).
    size : str
        ``"standard"`` (40 x 1000 train, 4 x 4000 valid and test) or ``"small"`` (16 x 400, 2 x 1600).
    seed : int
        Non-negative; seeds the excitations and the noise.
    noise : float
        Standard deviation of the measurement noise, as a fraction of each output's standard deviation
        over the noise-free training split (0: none).
    """
    if size not in MODEL_SIZES:
        raise ConfigError(f"unknown size {size!r} for a model of your own; valid sizes are {', '.join(MODEL_SIZES)}")
    from nnfmu.physics.registry import resolve_physics

    system = resolve_physics(system)
    cfg = MODEL_SIZES[size]
    config, limits = model_excitation(system)
    step = rk4_function(system.ode, Ts=system.Ts, n_sub=system.n_sub, name=f"{system.name}_rk4")
    splits = {"train": _split(system, step, config, limits, cfg.n_train, cfg.train_steps, seed, 0),
              "valid": _split(system, step, config, limits, cfg.n_valid, cfg.test_steps, seed, 2),
              "test": _split(system, step, config, limits, cfg.n_test, cfg.test_steps, seed, 1)}
    source = {"generator": "nnfmu.physics.generate_model", "system": system.name, "size": size, "seed": seed,
              "n_sub": system.n_sub, "params": {v.name: v.start for v in system.parameters},
              "config": dataclasses.asdict(cfg), "excitation": dataclasses.asdict(config),
              "model_source": dict(system.source)}
    ds = Dataset(Ts=system.Ts, inputs=tuple(Channel(v.name, v.unit, v.description) for v in system.inputs),
                 outputs=tuple(Channel(v.name, v.unit, v.description) for v in system.outputs),
                 splits=splits, source=source)
    return add_noise(ds, noise, seed)


def add_noise(ds: Dataset, noise: float, seed: int) -> Dataset:
    """``ds`` with white Gaussian noise on every output of every split (``ds`` itself when ``noise`` is 0).

    The noise's standard deviation is ``noise`` times each output's standard deviation over the training
    split; it is recorded in the source as ``noise`` and ``noise_std`` (in the outputs' units).
    """
    if not (np.isfinite(noise) and noise >= 0):
        raise ConfigError(f"noise must be a non-negative fraction of the output's standard deviation, got {noise!r}")
    if noise == 0:
        return ds
    sigma = noise * np.concatenate(ds.train.y).std(axis=0)
    rng = np.random.default_rng([seed, 99])
    splits = {k: Trajectories(t.u, tuple(y + sigma * rng.standard_normal(y.shape) for y in t.y))
              for k, t in ds.splits.items()}
    return dataclasses.replace(ds, splits=splits, source={**ds.source, "noise": noise, "noise_std": sigma.tolist()})
