"""Slider datasets: an integrating plant (force -> position) with long validation and test records.

Every record starts with the mass at rest (as an experiment on a real axis
does) at a random position in ``start_range``, and follows a random force
excitation. Starting at rest matters on an integrating plant: an initial speed
that the model does not know would shift the whole record (the position never
forgets it), whatever the model. The validation and test records are four
times longer than the training ones: the position wanders further than in any
training record, which is what an integrating plant does to a model trained on
short records.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from nnfmu.data import Channel, Dataset, Trajectories
from nnfmu.errors import ConfigError, SimulationError
from nnfmu.physics.base import params_to_json
from nnfmu.physics.registry import PhysicsEntry, StudyPreset, register_physics
from nnfmu.physics.rk4 import rk4_function
from nnfmu.physics.slider import SLIDER_F_MAX, SLIDER_TS, SliderParams, slider_system
from nnfmu.signals import ExcitationConfig, SignalLimits, excitation

__all__ = ["SliderDataConfig", "SLIDER_SIZES", "SLIDER_EXCITATION", "generate_slider"]

SLIDER_EXCITATION = ExcitationConfig(
    section_time=(1.0, 4.0),
    aprbs_hold=(0.2, 1.5),
    multisine_band=(0.05, 3.0),
    chirp_band=(0.05, 3.0),
    kinds=("hold", "ramp", "aprbs", "multisine", "chirp"),
    weights=(0.6, 0.6, 1.5, 1.0, 0.8),
    extreme_fraction=0.1,
)
_LIMITS = (SignalLimits(u_min=-SLIDER_F_MAX, u_max=SLIDER_F_MAX, rate_max=60.0),)


@dataclass(frozen=True, kw_only=True)
class SliderDataConfig:
    """Numbers of trajectories and samples per split; the range of the starting positions in m."""

    n_train: int
    train_steps: int
    n_valid: int
    n_test: int
    test_steps: int
    start_range: tuple[float, float] = (-5.0, 5.0)


SLIDER_SIZES = {
    "standard": SliderDataConfig(n_train=40, train_steps=1000, n_valid=4, n_test=4, test_steps=4000),
    "small": SliderDataConfig(n_train=16, train_steps=400, n_valid=2, n_test=2, test_steps=1600),
}


def _simulate(system, u: np.ndarray, pos0: float, n_sub: int) -> np.ndarray:
    """Positions (N, 1) of a free run from rest at ``pos0`` under the forces ``u`` (N, 1); sample k before u[k]."""
    step = rk4_function(system.ode, Ts=SLIDER_TS, n_sub=n_sub, name="slider_rk4")
    p = system.parameter_values()
    x0 = np.array([pos0, 0.0])
    xs = np.asarray(step.mapaccum("sim", len(u) - 1)(x0, u[:-1].T, np.repeat(p[:, None], len(u) - 1, 1)))
    x = np.hstack([x0[:, None], xs]).T
    if not np.isfinite(x).all():
        raise SimulationError("slider simulation produced non-finite states; check the parameters "
                              "(v_eps too small for Ts / n_sub?)")
    return x[:, :1]


def _split(system, cfg: SliderDataConfig, n_traj: int, n_steps: int, seed: int, split: int,
           n_sub: int) -> Trajectories:
    us, ys = [], []
    for i in range(n_traj):
        rng = np.random.default_rng([seed, split, i])
        pos0 = rng.uniform(*cfg.start_range)
        u = excitation(n_steps, Ts=SLIDER_TS, limits=_LIMITS, config=SLIDER_EXCITATION, seed=rng)
        us.append(u)
        ys.append(_simulate(system, u, pos0, n_sub))
    return Trajectories(tuple(us), tuple(ys))


def generate_slider(*, size: str = "standard", seed: int = 0, progress: bool = False,
                    params: SliderParams | None = None, n_sub: int = 4, partial_dir=None) -> Dataset:
    """Generate a slider dataset (input F in N; output pos in m; Ts = 10 ms): train, valid and test splits.

    Parameters
    ----------
    size : str
        A key of :data:`SLIDER_SIZES`: ``"standard"`` (40 x 1000 train, 4 x 4000 valid and test)
        or ``"small"`` (16 x 400 train, 2 x 1600 valid and test).
    seed : int
        Seeds every record's excitation and starting position.
    progress : bool
        Accepted for a uniform interface; the slider generates in seconds.
    params : SliderParams, optional
        Physical parameters (default :class:`SliderParams`).
    n_sub : int
        RK4 sub-steps per Ts.
    partial_dir : path, optional
        Not used: the slider generates in seconds, so it keeps no partial results.
    """
    if size not in SLIDER_SIZES:
        raise ConfigError(f"unknown slider dataset size {size!r}; valid sizes are {', '.join(SLIDER_SIZES)}")
    cfg, params = SLIDER_SIZES[size], params or SliderParams()
    system = slider_system(params)
    splits = {"train": _split(system, cfg, cfg.n_train, cfg.train_steps, seed, 0, n_sub),
              "valid": _split(system, cfg, cfg.n_valid, cfg.test_steps, seed, 2, n_sub),
              "test": _split(system, cfg, cfg.n_test, cfg.test_steps, seed, 1, n_sub)}
    source = {"generator": "nnfmu.physics.generate_slider", "system": "slider", "size": size, "seed": seed,
              "n_sub": n_sub, "params": params_to_json(params), "config": dataclasses.asdict(cfg),
              "excitation": dataclasses.asdict(SLIDER_EXCITATION),
              "position_range_m": {k: [float(min(y.min() for y in t.y)), float(max(y.max() for y in t.y))]
                                   for k, t in splits.items()}}
    return Dataset(Ts=SLIDER_TS, inputs=tuple(Channel(v.name, v.unit, v.description) for v in system.inputs),
                   outputs=tuple(Channel(v.name, v.unit, v.description) for v in system.outputs),
                   splits=splits, source=source)


SLIDER_STUDY = StudyPreset(
    name="slider", title="Slider, an integrating plant (generated data)", data_sizes=("standard", "small"),
    physics_label="Physics model (the slider model that generated the data, RK4)",
    note="The data were generated by the slider model (a mass with Stribeck friction driven by a force, its "
         "position measured): an integrating plant whose test positions go beyond the training range. Its physics "
         "row is the generator itself, exact up to the FMU's float64 arithmetic: every record starts at rest, as "
         "init(y0, u0) assumes.")

register_physics(PhysicsEntry("slider", slider_system, corrected_states=("v",), correction_time=0.1,
                              generate=generate_slider, sizes=tuple(SLIDER_SIZES),
                              title="Slider, a mass on a rail with friction", studies=(SLIDER_STUDY,)))
