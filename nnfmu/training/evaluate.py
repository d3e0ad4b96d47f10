"""Free-run evaluation: every score of a network is its free-run simulation (docs/design.md)."""

from __future__ import annotations

import copy

import numpy as np
import torch

from nnfmu.data import Trajectories
from nnfmu.metrics import NrmseResult, nrmse
from nnfmu.models.base import StepModel, torch_threads
from nnfmu.training.compiled_rollout import free_run_forward
from nnfmu.training.resources import check_threads

_EVAL_BATCH = 1024


def free_run(model: StepModel, traj: Trajectories, *, float64: bool = False,
             threads: int | None = None) -> list[np.ndarray]:
    """Free-run predictions ``[(n_i, n_y), ...]`` in physical units for every trajectory of ``traj``.

    Each trajectory starts from its measured ``y[0]``. Trajectories of equal
    length are simulated together in batches. With ``float64`` a float64 copy
    of the model runs (as :meth:`StepModel.simulate` does); otherwise the model
    runs in its own dtype, on the model's device, on ``threads`` intra-op threads (default one:
    :mod:`nnfmu.training.resources`). The model's train/eval mode is left unchanged.
    """
    runner = copy.deepcopy(model).double() if float64 else model
    dtype, device = runner.u_mean.dtype, runner.u_mean.device
    was_training = runner.training
    runner.eval()
    preds: list = [None] * traj.n_traj
    by_length: dict[int, list[int]] = {}
    for i, n in enumerate(traj.lengths.tolist()):
        by_length.setdefault(n, []).append(i)
    try:
        with torch.no_grad(), torch_threads(check_threads(threads)):
            for index in by_length.values():
                for start in range(0, len(index), _EVAL_BATCH):
                    chunk = index[start:start + _EVAL_BATCH]
                    u = torch.as_tensor(np.stack([traj.u[i] for i in chunk]), dtype=dtype, device=device)
                    y0 = torch.as_tensor(np.stack([traj.y[i][0] for i in chunk]), dtype=dtype, device=device)
                    y = free_run_forward(runner, u, y0).double().cpu().numpy()
                    for j, i in enumerate(chunk):
                        preds[i] = y[j]
    finally:
        runner.train(was_training)
    return preds


def free_run_nrmse(model: StepModel, traj: Trajectories, *, float64: bool = False) -> NrmseResult | None:
    """NRMSE of the free run on ``traj``; None if the simulation diverged (non-finite outputs)."""
    preds = free_run(model, traj, float64=float64)
    if not all(np.isfinite(p).all() for p in preds):
        return None
    return nrmse(list(traj.y), preds)


def score(model: StepModel, traj: Trajectories, *, float64: bool = False) -> float:
    """Mean free-run NRMSE, ``inf`` for a diverged simulation (so it never counts as best)."""
    result = free_run_nrmse(model, traj, float64=float64)
    return float("inf") if result is None else result.mean

