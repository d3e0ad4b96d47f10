"""How long the training and validation free runs are, and where they start.

- :func:`join_sequences`: training trajectories end to end (``TrainConfig.join``), so that the
  ``truncate``-sample windows can be as long as the free runs the model must survive.
- :func:`validation_trajectories`: the validation split as the free runs that choose the best
  epoch (``TrainConfig.valid_horizon``), and a note when they are much shorter than the test's.
- :func:`with_context`: a training window of ``N - 1 + T`` samples split into the init window's
  ``N - 1`` past samples and the ``T``-sample free run (multiple shooting with an init window).
- :func:`lr_factor`: the learning-rate schedule, a function of the progress through the epochs.
"""

from __future__ import annotations

import math

import torch

from nnfmu.data import Dataset, Trajectories
from nnfmu.training.batches import Batch
from nnfmu.training.config import TrainConfig

# Warn when the validation free runs are shorter than this fraction of the test trajectories.
SHORT_VALIDATION = 0.5


def join_sequences(seqs: list) -> list:
    """``[(un, yn), ...]`` -> one ``(un, yn)`` of all of them end to end, in order."""
    return [(torch.cat([u for u, _ in seqs]), torch.cat([y for _, y in seqs]))]


def validation_trajectories(ds: Dataset, cfg: TrainConfig) -> tuple[Trajectories, list[str]]:
    """The validation free runs of ``ds`` (which has a ``valid`` split) under ``cfg.valid_horizon``, and notes."""
    valid, notes = ds.valid, []
    test_len = int(ds.test.lengths.max()) if "test" in ds.splits else 0
    join = cfg.valid_horizon == "joined" or (
        cfg.valid_horizon == "auto" and bool(ds.source.get("contiguous")) and valid.n_traj > 1
        and test_len > int(valid.lengths.max()))
    if join:
        valid = valid.concatenated()
        notes.append(f"validating on the {ds.valid.n_traj} validation trajectories joined into one "
                     f"{valid.n_samples}-sample free run (valid_horizon={cfg.valid_horizon})")
    longest = int(valid.lengths.max())
    if test_len and longest < SHORT_VALIDATION * test_len:
        one = valid.n_traj == 1  # one record's tail: nothing to join
        fix = ("a larger valid_fraction (--valid-fraction), or a 'valid' split with a longer record" if one else
               "a 'valid' split with longer records, or valid_horizon='joined' if its trajectories are consecutive")
        notes.append(f"WARNING: the validation free runs cover at most {longest} samples but the test trajectories "
                     f"{test_len}: the epoch chosen on validation may drift over the test's horizon. Give {fix}")
    return valid, notes


def with_context(batch: Batch, context: int) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor | None, tuple | None]:
    """``(un, yn, mask, past)``: the free-run part of a batch and its first ``context`` samples as ``past``."""
    if context == 0:
        return batch.un, batch.yn, batch.mask, None
    past = (batch.yn[:, :context], batch.un[:, :context])
    mask = None if batch.mask is None else batch.mask[:, context:]
    return batch.un[:, context:], batch.yn[:, context:], mask, past


def lr_factor(cfg: TrainConfig, progress: float) -> float:
    """The learning rate as a fraction of ``cfg.lr`` at ``progress`` = epochs done / ``cfg.epochs`` (0 .. 1)."""
    if cfg.lr_schedule != "cosine":  # plateau and anneal lower it by steps: nnfmu.training.lr_plateau
        return 1.0
    t = min(max(progress, 0.0), 1.0)
    return cfg.lr_final + (1.0 - cfg.lr_final) * 0.5 * (1.0 + math.cos(math.pi * t))
