"""One entry point for generated datasets: :func:`generate_dataset` (used by ``nnfmu generate``).

Which generator and which sizes a model has comes from its registry entry (:mod:`nnfmu.physics.registry`):
a built-in model's own generator, or the toolkit's excitation signals for a model without one.
"""

from __future__ import annotations

from nnfmu.data import Dataset
from nnfmu.errors import ConfigError
from nnfmu.physics.generate_model import generate_model_dataset
from nnfmu.physics.registry import physics_entry

__all__ = ["generate_dataset", "check_request"]


def check_request(system: str, size: str, seed: int) -> None:
    """Raise :class:`ConfigError` (listing the valid choices) for an unknown system or size, or a bad seed."""
    entry = physics_entry(system)
    if size not in entry.sizes:
        raise ConfigError(f"unknown size {size!r} for the {system}; valid sizes are {', '.join(entry.sizes)}")
    if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
        raise ConfigError(f"seed must be a non-negative integer, got {seed!r}")


def generate_dataset(system: str, *, size: str = "small", seed: int = 0, progress: bool = False,
                     partial_dir=None) -> Dataset:
    """Simulate a registered physics model and return its dataset (train and test splits, some also valid).

    Parameters
    ----------
    system : str
        A registered model (:func:`nnfmu.physics.physics_names`), e.g.
        ``"valve"`` (inputs u1, u2 in V; outputs s in m, p in Pa; Ts = 40 us),
        ``"arm"`` (inputs tau1..tau6 motor torques in N.m; outputs q1..q6 in deg; Ts = 0.1 s) or
        ``"slider"`` (input F in N; output pos in m; Ts = 10 ms; an integrating plant).
    size : str
        One of the entry's ``sizes`` (the first is the full size).
        valve: ``"paper"`` (900 x 500 train, 30 x 3500 test) or ``"small"`` (40 x 300, 3 x 1500);
        arm: ``"benchmark"`` (11 x 3600 train, one 3600-sample test record) or ``"small"`` (2 x 300, 1 x 300);
        slider and a model without a generator of its own: ``"standard"`` (40 x 1000 train, 4 x 4000 valid
        and test) or ``"small"`` (16 x 400, 2 x 1600).
    seed : int
        Non-negative; the same seed gives the same dataset.
    progress : bool
        Show a tqdm progress bar (a model's own generator).
    partial_dir : path, optional
        Where a slow generator (the arm) keeps finished trajectories so that an interrupted run resumes
        (:mod:`nnfmu.physics.partial`); the others generate in seconds and do not use it.
    """
    entry = physics_entry(system)
    check_request(system, size, seed)
    if entry.generate is None:
        return generate_model_dataset(entry.build(), size=size, seed=seed)
    return entry.generate(size=size, seed=seed, progress=progress, partial_dir=partial_dir)
