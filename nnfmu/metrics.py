"""NRMSE, the one scoring rule of nnfmu (docs/design.md, "NRMSE: the scoring rule"), with RMSE, MAE, fit % and R².

For a trajectory and output k::

    NRMSE_k = RMSE_k / std_k,   std_k = std of the measured y_k over the horizon (ddof 0)
    RMSE_k  = sqrt(mean((y_k - yhat_k)^2)), in the output's own unit
    fit_k   = 100 (1 - NRMSE_k) %     (the "fit" of system identification toolboxes)
    MAE_k   = mean(|y_k - yhat_k|), in the output's own unit
    R2_k    = 1 - sum((y_k - yhat_k)^2) / sum((y_k - mean(y_k))^2) = 1 - NRMSE_k^2
              (the coefficient of determination; 1 is perfect, 0 is the measured mean, below 0 worse)

The trajectory's NRMSE is the mean over outputs, and a dataset's NRMSE is the
mean over its trajectories. The horizon is every sample handed in; the
toolkit's scoring path hands in the whole free-run simulation, whose first
sample is the measured ``y0``.

The paper prints the sum over outputs inside the square root, but compares its
robot results with the benchmark's baseline, which averages per-joint NRMSE;
nnfmu uses the per-output mean everywhere so that both datasets are scored
like the benchmark. RMSE, MAE, fit and R² are aggregated the same way (mean
over trajectories); RMSE and MAE are never averaged over outputs, whose units differ.
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
    rmse : ndarray, shape (n_traj, n_y)
        RMSE of each output on each trajectory, in the output's unit (None only for a result built by hand).
    mae : ndarray, shape (n_traj, n_y)
        Mean absolute error of each output on each trajectory, in the output's unit (None as ``rmse``).
    """

    per_output: np.ndarray
    per_trajectory: np.ndarray
    mean: float
    output_mean: np.ndarray
    rmse: np.ndarray | None = None
    mae: np.ndarray | None = None

    @property
    def rmse_output_mean(self) -> np.ndarray:
        """Per-output RMSE averaged over trajectories, shape (n_y,), in each output's unit."""
        return self.rmse.mean(axis=0)

    @property
    def mae_output_mean(self) -> np.ndarray:
        """Per-output MAE averaged over trajectories, shape (n_y,), in each output's unit."""
        return self.mae.mean(axis=0)

    @property
    def r2(self) -> float:
        """R² averaged over outputs and trajectories (as the NRMSE): 1 is perfect, 0 is the measured mean."""
        return float((1.0 - self.per_output**2).mean())

    @property
    def fit(self) -> float:
        """Fit in percent, ``100 (1 - NRMSE)``: 100 is perfect, 0 is no better than the measured mean."""
        return fit_percent(self.mean)

    def to_json(self, outputs: Sequence | None = None) -> dict:
        """Scores as JSON: the totals, then per output and per trajectory (each with NRMSE, RMSE, MAE, fit %, R²).

        ``outputs`` are the output names, or :class:`~nnfmu.data.Channel` objects whose units are
        recorded beside the RMSE. The keys ``nrmse``, ``per_output`` (name -> NRMSE) and
        ``per_trajectory`` (NRMSE list) stay as in earlier versions.
        """
        n_y = len(self.output_mean)
        outputs = list(outputs) if outputs is not None else [f"y{j + 1}" for j in range(n_y)]
        names = [getattr(o, "name", o) for o in outputs]
        units = [getattr(o, "unit", None) for o in outputs]
        rmse = self.rmse if self.rmse is not None else np.full(self.per_output.shape, np.nan)
        mae = self.mae if self.mae is not None else np.full(self.per_output.shape, np.nan)

        def cell(nrmse_value, rmse_value, mae_value, r2_value, unit=None) -> dict:
            out = {"nrmse": float(nrmse_value), "rmse": _finite(rmse_value), "mae": _finite(mae_value),
                   "fit_percent": fit_percent(nrmse_value), "r2": float(r2_value)}
            return out if unit is None else {"unit": unit, **out}

        r2 = 1.0 - self.per_output**2
        return {
            "nrmse": float(self.mean),
            "fit_percent": self.fit,
            "r2": self.r2,
            "per_output": {n: float(v) for n, v in zip(names, self.output_mean)},
            "per_trajectory": [float(v) for v in self.per_trajectory],
            "outputs": {n: cell(*values) for n, *values in
                        zip(names, self.output_mean, rmse.mean(axis=0), mae.mean(axis=0), r2.mean(axis=0), units)},
            "trajectories": [{"index": i, "nrmse": float(self.per_trajectory[i]),
                              "fit_percent": fit_percent(self.per_trajectory[i]), "r2": float(r2[i].mean()),
                              "outputs": {n: cell(*values) for n, *values in
                                          zip(names, self.per_output[i], rmse[i], mae[i], r2[i])}}
                             for i in range(len(self.per_trajectory))],
        }


def fit_percent(nrmse_value: float) -> float:
    """``100 (1 - NRMSE)``: the fit index in percent of one NRMSE value."""
    return float(100.0 * (1.0 - nrmse_value))


def _finite(x) -> float | None:
    x = float(x)
    return x if np.isfinite(x) else None


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
    rows, rmse_rows, mae_rows = [], [], []
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
        rmse_rows.append(np.sqrt(np.mean((t - p) ** 2, axis=0)))
        mae_rows.append(np.mean(np.abs(t - p), axis=0))
        rows.append(rmse_rows[-1] / std)
    if not rows:
        raise ShapeError("no trajectories to score")
    if len({r.shape for r in rows}) > 1:
        raise ShapeError("trajectories have different numbers of outputs")
    per_output = np.vstack(rows)
    per_traj = per_output.mean(axis=1)
    return NrmseResult(per_output, per_traj, float(per_traj.mean()), per_output.mean(axis=0), np.vstack(rmse_rows),
                       np.vstack(mae_rows))
