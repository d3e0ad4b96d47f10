"""One entry point for generated datasets: :func:`generate_dataset` (used by ``nnfmu generate``)."""

from __future__ import annotations

from nnfmu.data import Dataset
from nnfmu.errors import ConfigError

__all__ = ["generate_dataset", "check_request", "DATASET_SIZES"]

# Sizes per system; the first one is the full (paper or benchmark) size.
DATASET_SIZES = {"valve": ("paper", "small"), "arm": ("benchmark", "small"), "slider": ("standard", "small")}


def check_request(system: str, size: str, seed: int) -> None:
    """Raise :class:`ConfigError` (listing the valid choices) for an unknown system or size, or a bad seed."""
    if system not in DATASET_SIZES:
        raise ConfigError(f"unknown system {system!r}; valid systems are {', '.join(DATASET_SIZES)}")
    if size not in DATASET_SIZES[system]:
        raise ConfigError(f"unknown size {size!r} for the {system}; valid sizes are "
                          f"{', '.join(DATASET_SIZES[system])}")
    if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
        raise ConfigError(f"seed must be a non-negative integer, got {seed!r}")


def generate_dataset(system: str, *, size: str = "small", seed: int = 0, progress: bool = False,
                     partial_dir=None) -> Dataset:
    """Simulate a physics reference model and return its dataset (train and test splits).

    Parameters
    ----------
    system : str
        ``"valve"`` (inputs u1, u2 in V; outputs s in m, p in Pa; Ts = 40 us) or
        ``"arm"`` (inputs tau1..tau6 motor torques in N.m; outputs q1..q6 in deg; Ts = 0.1 s), or
        ``"slider"`` (input F in N; output pos in m; Ts = 10 ms; an integrating plant).
    size : str
        valve: ``"paper"`` (900 x 500 train, 30 x 3500 test) or ``"small"`` (40 x 300, 3 x 1500);
        arm: ``"benchmark"`` (11 x 3600 train, one 3600-sample test record) or ``"small"`` (2 x 300, 1 x 300);
        slider: ``"standard"`` (40 x 1000 train, 4 x 4000 valid and test) or ``"small"`` (16 x 400, 2 x 1600).
    seed : int
        Non-negative; the same seed gives the same dataset.
    progress : bool
        Show a tqdm progress bar.
    partial_dir : path, optional
        Where a slow generator (the arm) keeps finished trajectories so that an interrupted run resumes
        (:mod:`nnfmu.physics.partial`); the valve generates in seconds and does not use it.
    """
    check_request(system, size, seed)
    if system == "valve":
        from nnfmu.physics.generate_valve import generate_valve

        return generate_valve(size=size, seed=seed, progress=progress)
    if system == "slider":
        from nnfmu.physics.generate_slider import generate_slider

        return generate_slider(size=size, seed=seed, progress=progress)
    from nnfmu.physics.generate_arm import generate_arm

    return generate_arm(size=size, seed=seed, progress=progress, partial_dir=partial_dir)
