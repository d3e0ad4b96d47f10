"""Valve datasets: seeded excitation, RK4 simulation vectorised over trajectories, compiled to C.

Each trajectory starts from the valve at rest (both pilots closed, plunger on
its seat), holds zero volts for a random part of a warm-up and then follows a
random excitation (:mod:`nnfmu.signals`); only the samples after the warm-up
are recorded. So the recorded trajectories start from varied states, as
measured ones do.

The RK4 step (``n_sub`` sub-steps per Ts) is compiled once (:mod:`nnfmu.physics.compiled`)
and run as ``step.mapaccum(n_steps).map(batch)``: the whole loop stays in C.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from nnfmu.data import Channel, Dataset, Trajectories
from nnfmu.errors import ConfigError, SimulationError
from nnfmu.physics.base import params_to_json
from nnfmu.physics.compiled import compile_function
from nnfmu.physics.registry import PhysicsEntry, StudyPreset, register_physics
from nnfmu.physics.rk4 import rk4_function
from nnfmu.physics.valve import VALVE_TS, VALVE_U_MAX, ValveParams, valve_system
from nnfmu.signals import ExcitationConfig, SignalLimits, excitation_reference, slew_limit

__all__ = ["ValveDataConfig", "VALVE_SIZES", "VALVE_EXCITATION", "VALVE_RATE_MAX", "generate_valve"]

VALVE_RATE_MAX = 5e5  # V/s: a full 0 -> 250 V swing takes 0.5 ms (12.5 samples)
VALVE_EXCITATION = ExcitationConfig(
    section_time=(2e-3, 10e-3),
    aprbs_hold=(0.6e-3, 4e-3),
    multisine_band=(50.0, 1500.0),
    chirp_band=(20.0, 1500.0),
    kinds=("hold", "ramp", "aprbs", "multisine", "chirp"),
    weights=(1.0, 0.7, 1.5, 1.0, 0.8),
    extreme_fraction=0.25,
)
_LIMITS = (SignalLimits(u_min=0.0, u_max=VALVE_U_MAX, rate_max=VALVE_RATE_MAX),) * 2


@dataclass(frozen=True, kw_only=True)
class ValveDataConfig:
    """Shape of a generated valve dataset; times in seconds."""

    n_train: int
    train_steps: int
    n_test: int
    test_steps: int
    warmup: tuple[float, float] = (1e-3, 6e-3)
    batch: int = 64


VALVE_SIZES = {
    "paper": ValveDataConfig(n_train=900, train_steps=500, n_test=30, test_steps=3500),
    "small": ValveDataConfig(n_train=40, train_steps=300, n_test=3, test_steps=1500),
}

# Below these spreads a test trajectory would be (nearly) constant and NRMSE meaningless.
_MIN_STD = {"s": 2e-5, "p": 1e4}


def _references(cfg: ValveDataConfig, n_steps: int, seed: int, split: int, index: int) -> np.ndarray:
    """Reference (n_warm_max + n_steps, 2) of one trajectory: a zero hold, then the excitation.

    The random warm-up length gives every recorded trajectory its own initial state.
    """
    rng = np.random.default_rng([seed, split, index])
    n_warm_max = int(round(cfg.warmup[1] / VALVE_TS))
    n_warm = int(round(rng.uniform(*cfg.warmup) / VALVE_TS))
    active = excitation_reference(n_warm + n_steps, Ts=VALVE_TS, limits=_LIMITS, config=VALVE_EXCITATION, seed=rng)
    return np.vstack([np.zeros((n_warm_max - n_warm, 2)), active])


def _inputs(cfg: ValveDataConfig, n_steps: int, seed: int, split: int, index: range) -> tuple[np.ndarray, int]:
    """Slew-limited inputs (batch, n_warm_max + n_steps, 2) and the index where recording starts."""
    ref = np.stack([_references(cfg, n_steps, seed, split, i) for i in index])
    u = slew_limit(ref.transpose(0, 2, 1), Ts=VALVE_TS, rate_max=VALVE_RATE_MAX, u_min=0.0, u_max=VALVE_U_MAX,
                   u0=0.0).transpose(0, 2, 1)
    return u, int(round(cfg.warmup[1] / VALVE_TS))


class _Simulator:
    """Compiled batched RK4 free runs of the valve from its rest state."""

    def __init__(self, params: ValveParams, n_sub: int):
        self.system = valve_system(params)
        self.p = self.system.parameter_values()
        self.step = compile_function(rk4_function(self.system.ode, Ts=VALVE_TS, n_sub=n_sub, name="valve_rk4"))
        x = np.asarray(self.system.init_state([0.0, params.p_a], [0.0, 0.0], self.p)).ravel()
        # Settle the plunger on its seat so that the zero-volt warm-up starts from equilibrium.
        settle = self.step.mapaccum("settle", 500)(x, np.zeros((2, 500)), np.repeat(self.p[:, None], 500, 1))
        self.x_rest = np.asarray(settle)[:, -1]
        self._runs: dict[tuple[int, int], object] = {}

    def run(self, u: np.ndarray) -> np.ndarray:
        """``u`` (batch, N, 2) -> states (batch, N, 7) at t_0 .. t_{N-1} (state k is before input k acts)."""
        batch, n, _ = u.shape
        key = (batch, n)
        if key not in self._runs:
            self._runs[key] = self.step.mapaccum("sim", n - 1).map(batch)
        u_flat = u[:, :n - 1, :].reshape(batch * (n - 1), 2).T
        p = np.repeat(self.p[:, None], batch * (n - 1), 1)
        xs = np.asarray(self._runs[key](np.repeat(self.x_rest[:, None], batch, 1), u_flat, p))
        xs = xs.T.reshape(batch, n - 1, 7)
        return np.concatenate([np.broadcast_to(self.x_rest, (batch, 1, 7)), xs], axis=1)


def _split(sim: _Simulator, cfg: ValveDataConfig, n_traj: int, n_steps: int, seed: int, split: int,
           bar) -> Trajectories:
    us, ys = [], []
    for start in range(0, n_traj, cfg.batch):
        idx = range(start, min(start + cfg.batch, n_traj))
        u, k0 = _inputs(cfg, n_steps, seed, split, idx)
        x = sim.run(u)[:, k0:k0 + n_steps, :]
        if not np.isfinite(x).all():
            raise SimulationError(f"valve simulation produced non-finite states (seed {seed}); "
                                  "check the parameters (time constants too short for Ts / n_sub?)")
        us += list(u[:, k0:k0 + n_steps, :])
        ys += list(x[:, :, [5, 4]])  # outputs s, p
        if bar is not None:
            bar.update(len(idx))
    return Trajectories(tuple(us), tuple(ys))


def _statistics(tr: Trajectories, s_max: float) -> dict:
    s = np.concatenate([y[:, 0] for y in tr.y])
    return {"fraction_closed": float(np.mean(s < 0.02 * s_max)),
            "fraction_fully_open": float(np.mean(s > 0.98 * s_max)),
            "p_range_Pa": [float(min(y[:, 1].min() for y in tr.y)), float(max(y[:, 1].max() for y in tr.y))]}


def generate_valve(*, size: str = "small", seed: int = 0, progress: bool = False,
                   params: ValveParams | None = None, n_sub: int = 4, partial_dir=None) -> Dataset:
    """Generate a valve dataset (inputs u1, u2 in V; outputs s in m, p in Pa; Ts = 40 us).

    Parameters
    ----------
    size : str
        A key of :data:`VALVE_SIZES`: ``"paper"`` (900 x 500 train, 30 x 3500 test) or ``"small"``.
    seed : int
        Seeds every trajectory's excitation (trajectory ``i`` of a split depends only on ``seed``, split, ``i``).
    progress : bool
        Show a tqdm progress bar over trajectories.
    params : ValveParams, optional
        Physical parameters (default physics.md's table).
    n_sub : int
        RK4 sub-steps per sample.
    partial_dir : path, optional
        Not used: the valve generates in seconds, so it keeps no partial results.
    """
    if size not in VALVE_SIZES:
        raise ConfigError(f"unknown valve dataset size {size!r}; valid sizes are {', '.join(VALVE_SIZES)}")
    cfg, params = VALVE_SIZES[size], params or ValveParams()
    sim = _Simulator(params, n_sub)
    bar = None
    if progress:
        from nnfmu.progress import tqdm
        bar = tqdm(total=cfg.n_train + cfg.n_test, desc="valve trajectories", unit="traj")
    try:
        train = _split(sim, cfg, cfg.n_train, cfg.train_steps, seed, 0, bar)
        test = _split(sim, cfg, cfg.n_test, cfg.test_steps, seed, 1, bar)
    finally:
        if bar is not None:
            bar.close()
    _check_test_spread(test, seed)
    source = {"generator": "nnfmu.physics.generate_valve", "system": "valve", "size": size, "seed": seed,
              "n_sub": n_sub, "params": params_to_json(params), "config": dataclasses.asdict(cfg),
              "rate_max_V_per_s": VALVE_RATE_MAX, "excitation": dataclasses.asdict(VALVE_EXCITATION),
              "statistics": {"train": _statistics(train, params.s_max), "test": _statistics(test, params.s_max)}}
    return Dataset(Ts=VALVE_TS, inputs=tuple(Channel(v.name, v.unit, v.description) for v in sim.system.inputs),
                   outputs=tuple(Channel(v.name, v.unit, v.description) for v in sim.system.outputs),
                   splits={"train": train, "test": test}, source=source)


def _check_test_spread(test: Trajectories, seed: int) -> None:
    for i, y in enumerate(test.y):
        std = y.std(0)
        for j, (name, floor) in enumerate(_MIN_STD.items()):
            if std[j] < floor:
                raise SimulationError(f"test trajectory {i} (seed {seed}) has a nearly constant {name} "
                                      f"(std {std[j]:.3g} < {floor:g}); choose another seed")


# Valve linear refinement is left out of 'quick': on the paper-size data 30 Gauss-Newton evaluations took 3 minutes
# and changed nothing (0.5313 -> 0.5313). Generated valve data get 5 % measurement noise (nnfmu.study.budgets).
VALVE_STUDY = StudyPreset(
    name="valve", title="Pneumatic valve (generated data)", data_sizes=("paper", "small"), noise=0.05,
    linear_quick={"refine": False}, linear_paper={"refine": True},
    physics_label="Physics model (the valve model that generated the data, RK4)",
    note="The data were generated by the physics model, so its row is a reference (exact by "
         "construction{noise_floor}: only the integrator differs), not a competitor.")

register_physics(PhysicsEntry("valve", valve_system, corrected_states=("p", "sdot"), correction_time=1e-3,
                              generate=generate_valve, sizes=tuple(VALVE_SIZES), title="Pneumatic valve",
                              studies=(VALVE_STUDY,)))
