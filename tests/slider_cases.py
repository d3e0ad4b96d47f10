"""Small slider data shared by the tests of models on user physics (the hybrid on a model file, the neural ODE)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from nnfmu.data import Channel, Dataset, Trajectories, save_dataset
from nnfmu.physics import slider_system


def slider_dataset(seed: int, folder: Path) -> tuple[Dataset, Path]:
    """The built-in slider (Stribeck friction) under piecewise-constant forces (N), position out (m), Ts 10 ms:
    6 x 120 train, 2 valid, 1 test records from rest near 0; the dataset and the folder it is saved in."""
    truth, rng = slider_system(), np.random.default_rng(seed)

    def split(n_traj: int, n: int = 120) -> Trajectories:
        us, ys = [], []
        for _ in range(n_traj):
            u = np.repeat(rng.uniform(-6.0, 6.0, size=(n // 10 + 1, 1)), 10, axis=0)[:n]
            us.append(u)
            ys.append(truth.simulate_states(np.array([rng.uniform(-0.1, 0.1), 0.0]), u[:-1])[:, :1])
        return Trajectories(tuple(us), tuple(ys))

    ds = Dataset(Ts=0.01, inputs=(Channel("F", "N"),), outputs=(Channel("pos", "m"),),
                 splits={"train": split(6), "valid": split(2), "test": split(1)})
    return ds, save_dataset(ds, folder / "slider")
