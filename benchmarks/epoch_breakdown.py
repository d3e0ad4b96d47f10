"""Where a parallel training epoch spends its CPU time: batching, forward, backward, clipping, AdamW, validation.

The trainer's loop (nnfmu/training/session.py) timed part by part, on the generated valve data,
GRU-``--hidden``, whole trajectories or windows of ``--truncate``, one thread. Two paths run
interleaved, ``--repeats`` rounds of one epoch each: torch (the free run as torch operations,
AdamW's default implementation; ``NNFMU_COMPILED_ROLLOUT=0``) and nnfmu's default (the compiled
free run and fused AdamW). Prints each part's share of the epoch and trajectory-steps per
CPU-second (validation included), medians, and the ratio of the same run::

    taskset -c 1 python benchmarks/epoch_breakdown.py --size paper --batch 64
"""

from __future__ import annotations

import argparse
import os
import statistics
import time

import torch

from nnfmu.models import ModelConfig, build_model
from nnfmu.physics import generate_dataset
from nnfmu.training.batches import epoch_batches, masked_mse, normalised_sequences
from nnfmu.training.compiled_rollout import ENV_SWITCH, training_rollout
from nnfmu.training.evaluate import score
from nnfmu.training.resources import adamw

PARTS = ("batching", "forward", "backward", "clipping", "AdamW", "validation")


def one_epoch(model, seqs, valid, optimiser, batch: int, truncate: int | None, seed: int) -> tuple[dict, int]:
    """CPU seconds per part of one epoch, and the trajectory-steps trained."""
    spent, steps, clock = dict.fromkeys(PARTS, 0.0), 0, time.process_time
    model.train()
    rollout = training_rollout(model)
    batches = iter(epoch_batches(seqs, batch_size=batch, truncate=truncate,
                                 generator=torch.Generator().manual_seed(seed)))
    while True:
        t0 = clock()
        b = next(batches, None)
        t1 = clock()
        spent["batching"] += t1 - t0
        if b is None:
            break
        loss = masked_mse(rollout(b.un, b.yn), b.yn, b.mask)
        t2 = clock()
        optimiser.zero_grad(set_to_none=True)
        loss.backward()
        t3 = clock()
        torch.nn.utils.clip_grad_norm_(model.parameters(), 1.0)
        t4 = clock()
        optimiser.step()
        t5 = clock()
        for part, took in zip(PARTS[1:5], (t2 - t1, t3 - t2, t4 - t3, t5 - t4)):
            spent[part] += took
        steps += b.un.shape[0] * b.un.shape[1] if b.mask is None else int(b.mask.sum())
    t0 = clock()
    score(model, valid)
    spent["validation"] += clock() - t0
    return spent, steps


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--size", default="paper", choices=["small", "paper"])
    p.add_argument("--batch", type=int, default=64)
    p.add_argument("--hidden", type=int, default=32)
    p.add_argument("--truncate", type=int, default=None)
    p.add_argument("--repeats", type=int, default=2)
    args = p.parse_args()
    torch.set_num_threads(1)
    torch.set_flush_denormal(True)
    ds = generate_dataset("valve", size=args.size, seed=0).with_validation(0.1, seed=0)
    paths = {"torch": "0", "compiled": "1"}
    runs = {name: [] for name in paths}
    for r in range(args.repeats):
        for name, switch in paths.items():
            os.environ[ENV_SWITCH] = switch
            torch.manual_seed(0)
            model = build_model(ModelConfig(arch="gru", n_u=ds.n_u, n_y=ds.n_y, hidden=args.hidden),
                                norm=ds.norm_stats("train"))
            seqs = normalised_sequences(model, ds.train, torch.float32, "train")
            opt = (adamw(model.parameters(), lr=3e-3, weight_decay=1e-4) if switch == "1"
                   else torch.optim.AdamW(model.parameters(), lr=3e-3, weight_decay=1e-4))
            runs[name].append(one_epoch(model, seqs, ds.valid, opt, args.batch, args.truncate, r))
    os.environ.pop(ENV_SWITCH)
    print(f"valve {args.size}, GRU-{args.hidden}, batch {args.batch}, truncate {args.truncate}: one epoch, "
          f"median of {args.repeats} interleaved rounds, process CPU time")
    rates = {}
    for name, epochs in runs.items():
        rates[name] = statistics.median(steps / sum(spent.values()) for spent, steps in epochs)
        shares = {part: statistics.median(spent[part] / sum(spent.values()) for spent, _ in epochs) for part in PARTS}
        print(f"  {name:9s} {rates[name] / 1e3:7.0f}k trajectory-steps/CPU-s   "
              + ", ".join(f"{part} {100 * share:.1f} %" for part, share in shares.items()))
    print(f"  compiled / torch: {rates['compiled'] / rates['torch']:.2f}x per CPU-second")


if __name__ == "__main__":
    main()
