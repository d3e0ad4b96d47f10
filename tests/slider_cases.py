"""Small slider data shared by the tests of models on user physics (the hybrid on a model file, the neural ODE)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from nnfmu.data import Channel, Dataset, Trajectories, save_dataset
from nnfmu.physics import slider_system
from physics_sim import simulate_states


def slider_dataset(seed: int, folder: Path) -> tuple[Dataset, Path]:
    """The built-in slider (Stribeck friction) under piecewise-constant forces (N), position out (m), Ts 10 ms:
    6 x 120 train, 2 valid, 1 test records from rest near 0; the dataset and the folder it is saved in."""
    truth, rng = slider_system(), np.random.default_rng(seed)

    def split(n_traj: int, n: int = 120) -> Trajectories:
        us, ys = [], []
        for _ in range(n_traj):
            u = np.repeat(rng.uniform(-6.0, 6.0, size=(n // 10 + 1, 1)), 10, axis=0)[:n]
            us.append(u)
            ys.append(simulate_states(truth, np.array([rng.uniform(-0.1, 0.1), 0.0]), u[:-1])[:, :1])
        return Trajectories(tuple(us), tuple(ys))

    ds = Dataset(Ts=0.01, inputs=(Channel("F", "N"),), outputs=(Channel("pos", "m"),),
                 splits={"train": split(6), "valid": split(2), "test": split(1)})
    return ds, save_dataset(ds, folder / "slider")


def model_exchange_and_co_simulation(fmu: Path, ds: Dataset, u: np.ndarray, y0: np.ndarray) -> dict[str, np.ndarray]:
    """``{"CoSimulation": pos, "ModelExchange": pos}`` of a slider FMU in fmpy under the force ``u`` (N, 1), both
    from the measured ``y0``, at the samples (not at the input's events): Model Exchange with CVode at a relative
    tolerance of 1e-10, the input held between samples (a step, no ramp)."""
    import fmpy

    t = np.arange(len(u)) * ds.Ts
    steps = [(t[k], u[k - 1, 0]) for k in range(1, len(u)) if u[k, 0] != u[k - 1, 0]]
    signal = np.array(sorted(steps + list(zip(t, u[:, 0])), key=lambda row: row[0]),
                      dtype=[("time", float), ("F", float)])
    runs = {}
    for kind, options in (("CoSimulation", {}), ("ModelExchange", {"solver": "CVode", "relative_tolerance": 1e-10})):
        result = fmpy.simulate_fmu(str(fmu), fmi_type=kind, stop_time=t[-1], output_interval=ds.Ts,
                                   input=signal, start_values={"pos_start": float(y0[0])}, **options)
        rows = [np.flatnonzero(np.abs(result["time"] - t_k) < 1e-6 * ds.Ts)[-1] for t_k in t]
        runs[kind] = result["pos"][rows]
    return runs
