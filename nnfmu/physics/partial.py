"""Resumable generation: finished trajectories are kept in a partial folder until the dataset is written.

Slow generators (the arm: CVODES in closed loop, seconds per trajectory) store
every finished trajectory as ``<split>_<index>.npz`` in a folder beside the
target. A rerun with the same request (system, size, seed, parameters; checked
through ``request.json``) loads them instead of simulating again, so stopping
generation loses at most the trajectory in progress. A different request
empties the folder first.
"""

from __future__ import annotations

import json
import os
import shutil
from pathlib import Path

import numpy as np

from nnfmu.atomic import write_atomic


class PartialTrajectories:
    """Per-trajectory store for one generation request; ``folder=None`` disables it."""

    def __init__(self, folder: str | os.PathLike | None, request: dict):
        self.folder = None if folder is None else Path(folder)
        if self.folder is None:
            return
        stamp = self.folder / "request.json"
        text = json.dumps(request, sort_keys=True)
        if self.folder.exists() and (not stamp.exists() or stamp.read_text() != text):
            shutil.rmtree(self.folder)
        self.folder.mkdir(parents=True, exist_ok=True)
        stamp.write_text(text)

    def _file(self, split: int, index: int) -> Path:
        return self.folder / f"{split}_{index}.npz"

    def load(self, split: int, index: int) -> tuple[np.ndarray, np.ndarray] | None:
        """``(u, y)`` of a finished trajectory, or None if it still has to be simulated."""
        if self.folder is None or not self._file(split, index).exists():
            return None
        try:
            with np.load(self._file(split, index)) as z:
                return z["u"], z["y"]
        except (OSError, ValueError, KeyError):  # a damaged file is simulated again
            return None

    def store(self, split: int, index: int, u: np.ndarray, y: np.ndarray) -> None:
        if self.folder is None:
            return
        write_atomic(self._file(split, index), lambda tmp: np.savez(tmp, u=u, y=y), suffix=".npz")
