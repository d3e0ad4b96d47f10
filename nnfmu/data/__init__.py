"""Datasets: the container, its folder on disk, and loaders for external formats."""

from nnfmu.data.dataset import (
    SPLIT_NAMES,
    Channel,
    Dataset,
    NormStats,
    Trajectories,
    from_arrays,
    make_trajectories,
)
from nnfmu.data.benchmarks import from_benchmark
from nnfmu.data.importing import load_files
from nnfmu.data.loaders import load_csv, load_robot_benchmark
from nnfmu.data.storage import load_dataset, save_dataset

__all__ = [
    "SPLIT_NAMES",
    "Channel",
    "Dataset",
    "NormStats",
    "Trajectories",
    "from_arrays",
    "from_benchmark",
    "load_files",
    "make_trajectories",
    "load_csv",
    "load_robot_benchmark",
    "load_dataset",
    "save_dataset",
]
