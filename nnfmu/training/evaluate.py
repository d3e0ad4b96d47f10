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


def free_run(model: StepModel, traj: Trajectories, *, float64: bool = False, context: int = 1,
             threads: int | None = None) -> list[np.ndarray]:
    """Free-run predictions ``[(n_i - context + 1, n_y), ...]`` in physical units for every trajectory of ``traj``.

    Each trajectory starts from its measured ``y[context - 1]``; with ``context = N > 1`` the
    model's init window sees the samples before it (``N`` must be the model's ``init_window``,
    or the model must have none, which then starts from ``y[N - 1]`` alone). Trajectories of equal
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
                    y = torch.as_tensor(np.stack([traj.y[i] for i in chunk]), dtype=dtype, device=device)
                    if context > 1 and runner.config.init_window > 1:
                        past = {"y_past": y[:, :context - 1], "u_past": u[:, :context - 1]}
                        y = runner(u[:, context - 1:], y[:, context - 1], **past)
                    else:
                        y = free_run_forward(runner, u[:, context - 1:], y[:, context - 1])
                    y = y.double().cpu().numpy()
                    for j, i in enumerate(chunk):
                        preds[i] = y[j]
    finally:
        runner.train(was_training)
    return preds


def free_run_nrmse(model: StepModel, traj: Trajectories, *, float64: bool = False,
                   context: int = 1) -> NrmseResult | None:
    """NRMSE of the free run on ``traj``; None if the simulation diverged (non-finite outputs).

    ``context = 1``: the free run from the measured ``y[0]``, scored on every sample. ``context = N > 1``:
    the model sees samples ``0 .. N-1`` (its init window) and is scored on samples ``N ..`` (the
    benchmarks' protocol with an initialisation window of N samples).
    """
    preds = free_run(model, traj, float64=float64, context=context)
    if not all(np.isfinite(p).all() for p in preds):
        return None
    if context == 1:
        return nrmse(list(traj.y), preds)
    return nrmse([y[context:] for y in traj.y], [p[1:] for p in preds])


def score(model: StepModel, traj: Trajectories, *, float64: bool = False, context: int = 1) -> float:
    """Mean free-run NRMSE, ``inf`` for a diverged simulation (so it never counts as best)."""
    result = free_run_nrmse(model, traj, float64=float64, context=context)
    return float("inf") if result is None else result.mean

