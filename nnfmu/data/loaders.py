"""Loaders that turn external formats into a :class:`~nnfmu.data.Dataset`.

- :func:`load_robot_benchmark`: the industrial robot benchmark's official
  ``.mat`` (Weigand et al. 2022), and the re-cut variant with 605-sample pieces;
- :func:`load_csv`: CSV files with a header of named columns (a thin front of
  :func:`nnfmu.data.importing.load_files`, which also reads ``.mat`` and ``.npz``).
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Mapping, Sequence

import numpy as np

from nnfmu.data.dataset import Channel, Dataset, Trajectories, make_trajectories
from nnfmu.data.importing import load_files
from nnfmu.data.tables import read_mat
from nnfmu.errors import DataFileError, ShapeError

ROBOT_TS = 0.1
ROBOT_INPUTS = tuple(Channel(f"tau{j}", "N.m", f"motor torque of joint {j}") for j in range(1, 7))
ROBOT_OUTPUTS = tuple(Channel(f"q{j}", "deg", f"angle of joint {j}") for j in range(1, 7))
RECUT_PIECE = 605
RECUT_CAVEAT = (
    "NOT the original benchmark file: a re-cut variant (yifang0-0/Physics-Guided-Recurrent-State-"
    "Space-Neural-Networks) in 605-sample pieces, with one position and one torque sample dropped "
    "per 606-sample piece, padded validation tail (trimmed here), and uncertain u/y alignment. "
    "Scores on it are near, not equal, to official benchmark figures; do not report them as official."
)


def _channel_major(mat: dict, key: str, path: Path) -> np.ndarray:
    """Return ``mat[key]`` (6 x N, channel-major) as an array of shape (N, 6)."""
    arr = mat[key]
    if arr.ndim != 2 or 6 not in arr.shape:
        raise ShapeError(f"{path}: array {key!r} has shape {arr.shape}, expected (6, N) channel-major")
    return np.ascontiguousarray(arr.T if arr.shape[0] == 6 else arr, dtype=np.float64)


def load_robot_benchmark(path: str | os.PathLike, *, recut_piece: int = RECUT_PIECE) -> Dataset:
    """Load the industrial robot benchmark (KUKA KR300 R2500) from its ``.mat`` file.

    Two layouts are recognised:

    - **official** ``forward_identification_without_raw_data.mat``: ``time_train``,
      ``time_test`` (1, N) in s, ``u_train``, ``u_test`` (6, N) motor torques in
      N.m and ``y_train``, ``y_test`` (6, N) joint angles in deg. Train and test
      each become one continuous trajectory; Ts is the median time step. There
      is no official validation split (use ``Dataset.with_validation``).
    - **re-cut variant** (``u_train``, ``u_val``, ``u_test``, ... with no time
      vectors): every split is cut into ``recut_piece``-sample pieces, because
      a sample was dropped at each piece boundary. The test pieces are joined
      into one record, as the benchmark scores its test set. Padding at the end
      of a split (inputs exactly zero on all channels) is trimmed. ``source``
      records the caveat.

    Returns a dataset with inputs ``tau1..tau6`` [N.m] and outputs ``q1..q6`` [deg].
    """
    path = Path(path)
    mat = read_mat(path)
    needed = {"u_train", "y_train", "u_test", "y_test"}
    if not needed <= set(mat):
        raise DataFileError(
            f"{path} lacks {sorted(needed - set(mat))}; expected the benchmark layout with "
            "u_train, y_train, u_test, y_test (6 x N each)"
        )
    arr = {k: _channel_major(mat, k, path) for k in needed | ({"u_val", "y_val"} & set(mat))}
    for s in ("train", "test", "val"):
        if f"u_{s}" in arr and len(arr[f"u_{s}"]) != len(arr[f"y_{s}"]):
            raise ShapeError(f"{path}: u_{s} has {len(arr[f'u_{s}'])} samples but y_{s} has "
                             f"{len(arr[f'y_{s}'])}")
    if "time_train" in mat:
        return _official(path, mat, arr)
    return _recut(path, arr, recut_piece)


def _official(path: Path, mat: dict, arr: dict) -> Dataset:
    t = np.ravel(mat["time_train"]).astype(float)
    if len(t) != len(arr["u_train"]):
        raise ShapeError(f"{path}: time_train has {len(t)} samples but u_train has {len(arr['u_train'])}")
    dt = np.diff(t)
    Ts = float(np.median(dt)) if len(dt) else ROBOT_TS
    splits = {
        "train": make_trajectories(arr["u_train"], arr["y_train"], "train"),
        "test": make_trajectories(arr["u_test"], arr["y_test"], "test"),
    }
    source = {"kind": "robot-benchmark", "layout": "official", "file": str(path.resolve()),
              "reference": "Weigand et al. 2022, doi:10.26204/DATA/5"}
    return Dataset(Ts=Ts, inputs=ROBOT_INPUTS, outputs=ROBOT_OUTPUTS, splits=splits, source=source)


def _pieces(u: np.ndarray, y: np.ndarray, piece: int) -> Trajectories:
    us = [u[i:i + piece] for i in range(0, len(u), piece)]
    ys = [y[i:i + piece] for i in range(0, len(y), piece)]
    last = us[-1]
    pad = 0
    while pad < len(last) and not last[len(last) - 1 - pad].any():
        pad += 1
    if pad:  # zero-torque padding, and the output samples held beside it
        us[-1], ys[-1] = last[:len(last) - pad - 1], ys[-1][:len(last) - pad - 1]
    keep = [i for i, a in enumerate(us) if len(a) >= 2]
    return Trajectories(tuple(us[i] for i in keep), tuple(ys[i] for i in keep))


def _recut(path: Path, arr: dict, piece: int) -> Dataset:
    splits = {"train": _pieces(arr["u_train"], arr["y_train"], piece),
              "test": _pieces(arr["u_test"], arr["y_test"], piece).concatenated()}
    if "u_val" in arr:
        splits["valid"] = _pieces(arr["u_val"], arr["y_val"], piece)
    # contiguous: each split's pieces follow each other in time (one recording, a sample dropped per cut),
    # so training windows and validation runs may span several pieces (nnfmu.training.horizons).
    source = {"kind": "robot-benchmark", "layout": "recut-605", "file": str(path.resolve()),
              "caveat": RECUT_CAVEAT, "piece_length": piece, "contiguous": True,
              "reference": "Weigand et al. 2022, doi:10.26204/DATA/5"}
    return Dataset(Ts=ROBOT_TS, inputs=ROBOT_INPUTS, outputs=ROBOT_OUTPUTS, splits=splits, source=source)


def load_csv(
    files,
    *,
    inputs,
    outputs,
    Ts: float | None = None,
    time_column: str | int | None = None,
    units: Mapping[str, str] | Sequence[str] | None = None,
    columns: Mapping | None = None,
    **options,
) -> Dataset:
    """Build a dataset from CSV files, each one trajectory, with a header row of column names (or none).

    ``files`` maps a split name (``train``, ``valid``, ``test``) to one CSV file or a list of
    them; a single path or list holds the training files. ``inputs`` and ``outputs`` name the
    columns to use, in order (names, 0-based indices, or ``{channel name: column}``). The sample
    time is ``Ts`` or the median step of ``time_column``. ``units`` maps channel names to units.
    ``columns`` gives splits their own columns of the same files, for a file like
    ``uEst, uVal, yEst, yVal``::

        load_csv("data.csv", inputs={"u": "uEst"}, outputs={"y": "yEst"}, Ts=4.0,
                 columns={"test": {"u": "uVal", "y": "yVal"}})

    A test split is required, and a split that would read the training columns of the training
    files is refused (it would silently score on the training data). ``options`` are those of
    :func:`nnfmu.data.importing.load_files` (``resample``, ``valid_fraction``, ``valid_trajectories``, ``seed``).
    """
    return load_files(files, inputs=inputs, outputs=outputs, Ts=Ts, time_column=time_column, units=units,
                      columns=columns, fmt="csv", **options)
