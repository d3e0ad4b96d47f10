"""NRMSE, the one scoring rule of nnfmu (DESIGN.md, "NRMSE: the scoring rule").

For a trajectory and output k::

    NRMSE_k = RMSE_k / std_k,   std_k = std of the measured y_k over the horizon (ddof 0)

The trajectory's NRMSE is the mean over outputs, and a dataset's NRMSE is the
mean over its trajectories. The horizon is every sample handed in; the
toolkit's scoring path hands in the whole free-run simulation, whose first
sample is the measured ``y0``.

The paper prints the sum over outputs inside the square root, but compares its
robot results with the benchmark's baseline, which averages per-joint NRMSE;
nnfmu uses the per-output mean everywhere so that both datasets are scored
like the benchmark.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np

from nnfmu.errors import MetricError, ShapeError


@dataclass(frozen=True)
class NrmseResult:
    """Scores of a set of trajectories.

    Attributes
    ----------
    per_output : ndarray, shape (n_traj, n_y)
        NRMSE of each output on each trajectory.
    per_trajectory : ndarray, shape (n_traj,)
        Mean over outputs, per trajectory.
    mean : float
        Mean over trajectories: the dataset's NRMSE.
    output_mean : ndarray, shape (n_y,)
        Per-output NRMSE averaged over trajectories.
    """

    per_output: np.ndarray
    per_trajectory: np.ndarray
    mean: float
    output_mean: np.ndarray

    def to_json(self, output_names: Sequence[str] | None = None) -> dict:
        names = list(output_names) if output_names is not None else [f"y{j + 1}" for j in range(len(self.output_mean))]
        return {
            "nrmse": float(self.mean),
            "per_output": {n: float(v) for n, v in zip(names, self.output_mean)},
            "per_trajectory": [float(v) for v in self.per_trajectory],
        }


def _as_list(a, what: str) -> list[np.ndarray]:
    if isinstance(a, np.ndarray):
        if a.ndim == 2:
            return [a.astype(np.float64)]
        if a.ndim == 3:
            return [t.astype(np.float64) for t in a]
        raise ShapeError(f"{what} has shape {a.shape}, expected (n_steps, n_y) or (n_traj, n_steps, n_y)")
    return [np.asarray(t, dtype=np.float64) for t in a]


def nrmse(y_true, y_pred) -> NrmseResult:
    """Score predictions against measurements.

    Parameters
    ----------
    y_true, y_pred : array of shape (n_steps, n_y) or (n_traj, n_steps, n_y), or a list of
        (n_steps_i, n_y) arrays for trajectories of different lengths. Physical units.

    Raises
    ------
    ShapeError
        If the two do not have the same trajectories and shapes.
    MetricError
        If a measured output is constant over a trajectory (std 0) or a value is not finite.
    """
    ts, ps = _as_list(y_true, "y_true"), _as_list(y_pred, "y_pred")
    if len(ts) != len(ps):
        raise ShapeError(f"y_true has {len(ts)} trajectories but y_pred has {len(ps)}")
    rows = []
    for i, (t, p) in enumerate(zip(ts, ps)):
        if t.shape != p.shape or t.ndim != 2:
            raise ShapeError(f"trajectory {i}: y_true has shape {t.shape} but y_pred has {p.shape}; "
                             "both must be (n_steps, n_y)")
        if not (np.isfinite(t).all() and np.isfinite(p).all()):
            raise MetricError(f"trajectory {i}: non-finite values in {'y_true' if not np.isfinite(t).all() else 'y_pred'}"
                              "; a diverged simulation cannot be scored")
        std = t.std(axis=0)
        if (std == 0).any():
            j = int(np.flatnonzero(std == 0)[0])
            raise MetricError(f"trajectory {i}: measured output {j} is constant, so its NRMSE is undefined; "
                              "drop that trajectory or output from the scored split")
        rows.append(np.sqrt(np.mean((t - p) ** 2, axis=0)) / std)
    if not rows:
        raise ShapeError("no trajectories to score")
    if len({r.shape for r in rows}) > 1:
        raise ShapeError("trajectories have different numbers of outputs")
    per_output = np.vstack(rows)
    per_traj = per_output.mean(axis=1)
    return NrmseResult(per_output, per_traj, float(per_traj.mean()), per_output.mean(axis=0))
