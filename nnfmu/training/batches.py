"""Training batches: normalised trajectories, optional truncation windows, padding masks.

Trajectories may differ in length. Truncated windows all have the same length
and are simply stacked. Whole trajectories of different lengths are padded to
the longest one of their batch and a mask keeps the padding out of the loss;
the models are causal, so padding after a trajectory's end cannot change its
predictions.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Iterator

import torch

from nnfmu.data import Trajectories
from nnfmu.errors import DataError
from nnfmu.models.base import StepModel


@dataclass(frozen=True)
class Batch:
    """Normalised inputs ``un`` (B, T, n_u), outputs ``yn`` (B, T, n_y), and ``mask`` (B, T) or None."""

    un: torch.Tensor
    yn: torch.Tensor
    mask: torch.Tensor | None


def normalised_sequences(model: StepModel, traj: Trajectories, dtype: torch.dtype, split: str) -> list:
    """``[(un_i (n_i, n_u), yn_i (n_i, n_y)), ...]`` in normalised units; DataError on non-finite values."""
    out = []
    with torch.no_grad():
        for i, (u, y) in enumerate(zip(traj.u, traj.y)):
            un = model.normalise_u(torch.tensor(u, dtype=dtype))
            yn = model.normalise_y(torch.tensor(y, dtype=dtype))
            if not (torch.isfinite(un).all() and torch.isfinite(yn).all()):
                raise DataError(f"{split} trajectory {i} has non-finite values after normalisation (NaN, inf, or "
                                f"values beyond {dtype} range); clean the data or train in float64")
            out.append((un, yn))
    return out


def _windows(seqs: list, length: int, generator: torch.Generator) -> list:
    """Cut each sequence into windows of ``length`` samples from a random offset (none straddles two)."""
    out = []
    for un, yn in seqs:
        n = len(un)
        if n < length:
            continue
        offset = int(torch.randint(0, min(length, n - length + 1), (1,), generator=generator))
        for start in range(offset, n - length + 1, length):
            out.append((un[start:start + length], yn[start:start + length]))
    return out


def _pad(seqs: list) -> Batch:
    lengths = [len(un) for un, _ in seqs]
    if len(set(lengths)) == 1:
        return Batch(torch.stack([s[0] for s in seqs]), torch.stack([s[1] for s in seqs]), None)
    T = max(lengths)
    # pad by repeating the last sample: finite, in range, and masked out of the loss
    un = torch.stack([torch.cat([u, u[-1:].expand(T - len(u), -1)]) for u, _ in seqs])
    yn = torch.stack([torch.cat([y, y[-1:].expand(T - len(y), -1)]) for _, y in seqs])
    mask = torch.arange(T, device=un.device)[None, :] < torch.tensor(lengths, device=un.device)[:, None]
    return Batch(un, yn, mask)


def epoch_batches(seqs: list, *, batch_size: int, truncate: int | None,
                  generator: torch.Generator) -> Iterator[Batch]:
    """Shuffled batches of one epoch, drawn with ``generator``."""
    items = seqs if truncate is None else _windows(seqs, truncate, generator)
    if not items:
        longest = max(len(un) for un, _ in seqs)
        raise DataError(f"no training trajectory has {truncate} samples (the longest has {longest}); "
                        "choose a smaller truncate")
    order = torch.randperm(len(items), generator=generator).tolist()
    for start in range(0, len(order), batch_size):
        yield _pad([items[i] for i in order[start:start + batch_size]])


def masked_mse(pred: torch.Tensor, target: torch.Tensor, mask: torch.Tensor | None) -> torch.Tensor:
    """Mean squared error over samples 1..T-1 (sample 0 is the given y0), ignoring padding."""
    err = (pred[:, 1:] - target[:, 1:]).square()
    if mask is None:
        return err.mean()
    m = mask[:, 1:, None].to(err.dtype)
    return (err * m).sum() / (m.sum() * err.shape[-1])
