"""Training throughput in trajectory-steps per CPU-second on the valve paper shape: threads and strategies.

The paper's valve data: 900 training trajectories of 500 steps, 2 inputs, 2
outputs. One "trajectory-step" is one sample of one trajectory through the
forward pass, the backward pass and the AdamW update. The data are random
(throughput does not depend on the values). Figures are trajectory-steps per
second of process CPU time (``time.process_time``: all threads of the process
count), and wall-clock rates beside them; the variants are run interleaved,
``--repeats`` rounds, and the median is printed with the ratios measured in
the same run. Pin it on a shared machine: the threads comparison to as many
cores as its threads (it refuses fewer), the others to one core::

    taskset -c 0,1 python benchmarks/train_throughput.py --compare threads --many-threads 2
    taskset -c 1 python benchmarks/train_throughput.py --compare strategies --archs gru lstm --hidden 32
    taskset -c 1 python benchmarks/train_throughput.py --compare paths --archs gru lstm --hidden 32

Comparisons (``--compare``):

- ``threads``: ``--many-threads`` torch threads (default 2; ``torch.set_num_threads``, on at
  least as many cores of the process's affinity) against one thread, the nnfmu default
  (:mod:`nnfmu.training.resources`). Under ``taskset -c 1`` torch's own default is one thread,
  so the two arms would be the same: the comparison sets the count itself;
- ``strategies``: parallel against series-parallel, for each ``--archs``;
- ``paths``: the parallel update in torch (the free run as torch operations, AdamW's
  default implementation: nnfmu before the compiled paths; ``NNFMU_COMPILED_ROLLOUT=0`` while it runs)
  against nnfmu's training path (the compiled free run, :mod:`nnfmu.training.compiled_rollout`, or the ss
  network's compiled state loop, :mod:`nnfmu.ss.compiled`, and fused AdamW).
"""

from __future__ import annotations

import argparse
import os
import statistics
import time

import torch

from nnfmu.models import ModelConfig, build_model
from nnfmu.training.batches import masked_mse
from nnfmu.training.compiled_rollout import ENV_SWITCH, training_rollout
from nnfmu.training.resources import adamw

N_TRAJ, N_STEPS, N_U, N_Y = 900, 500, 2, 2


def plain_adamw(params):
    return torch.optim.AdamW(params, lr=1e-3)


def nnfmu_adamw(params):
    return adamw(params, lr=1e-3, weight_decay=0.01)  # AdamW's default weight decay, as plain_adamw


def time_updates(rollout, model, un, yn, batch: int, n_batches: int, optimiser=plain_adamw) -> tuple[float, float]:
    """(CPU seconds, wall seconds) of ``n_batches`` optimiser steps of ``rollout(un_b, yn_b) -> pred``."""
    opt = optimiser(model.parameters())
    c0, t0 = time.process_time(), time.perf_counter()
    for b in range(n_batches):
        idx = slice(b * batch, (b + 1) * batch)
        loss = masked_mse(rollout(un[idx], yn[idx]), yn[idx], None)
        opt.zero_grad(set_to_none=True)
        loss.backward()
        torch.nn.utils.clip_grad_norm_(model.parameters(), 1.0)
        opt.step()
    return time.process_time() - c0, time.perf_counter() - t0


def check_cores(many: int, cores: set[int] | None = None) -> None:
    """Refuse a threads comparison of ``many`` threads on fewer cores than that (``cores``: the affinity)."""
    cores = os.sched_getaffinity(0) if cores is None else cores
    if many < 2:
        raise SystemExit(f"train_throughput.py: --many-threads {many} compares nothing with 1 thread; use 2 or more")
    if len(cores) < many:
        raise SystemExit(f"train_throughput.py: --many-threads {many} on {len(cores)} core(s) {sorted(cores)}; "
                         f"pin to {many} cores, e.g. taskset -c 0-{many - 1}")


def in_torch(rollout):
    """``rollout`` with the compiled paths off while its forward runs (its backward is then torch's autograd)."""
    def run(u, y):
        before = os.environ.get(ENV_SWITCH)
        os.environ[ENV_SWITCH] = "0"
        try:
            return rollout(u, y)
        finally:
            if before is None:
                del os.environ[ENV_SWITCH]
            else:
                os.environ[ENV_SWITCH] = before
    return run


def variants(kind: str, model, threads: int | None, many: int = 2) -> dict:
    """name -> (rollout, threads, optimiser) of the comparison ``kind`` (``many``: the threads arm's count)."""
    parallel = lambda u, y: model.rollout_normalised(u, y[:, 0])  # noqa: E731
    one = threads or 1
    if kind == "threads":
        return {f"{many} threads": (parallel, many, plain_adamw),
                "1 thread (nnfmu default)": (parallel, 1, plain_adamw)}
    if kind == "paths":
        model.train()
        return {"torch free run, AdamW": (in_torch(parallel), one, plain_adamw),
                "compiled free run, fused AdamW": (training_rollout(model), one, nnfmu_adamw)}
    return {"parallel": (parallel, one, plain_adamw),
            "series-parallel": (lambda u, y: model.rollout_normalised(u, y[:, 0], y), one, plain_adamw)}


def measure(runs: dict, model, un, yn, batch: int, n_batches: int, repeats: int) -> dict:
    """Interleaved repeats; name -> (median CPU rate, median wall rate, every CPU rate) in trajectory-steps/s."""
    cpu, wall = {k: [] for k in runs}, {k: [] for k in runs}
    steps = n_batches * batch * N_STEPS
    for _ in range(repeats):
        for name, (rollout, threads, optimiser) in runs.items():
            torch.set_num_threads(threads)
            c, w = time_updates(rollout, model, un, yn, batch, n_batches, optimiser)
            cpu[name].append(steps / c)
            wall[name].append(steps / w)
    return {k: (statistics.median(cpu[k]), statistics.median(wall[k]), cpu[k]) for k in runs}


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--compare", choices=["threads", "strategies", "paths"], default="threads")
    p.add_argument("--archs", nargs="+", default=["gru"])
    p.add_argument("--hidden", type=int, default=64)
    p.add_argument("--batch-sizes", nargs="+", type=int, default=[64, 900])
    p.add_argument("--batches", type=int, default=2, help="optimiser steps timed per run")
    p.add_argument("--repeats", type=int, default=3)
    p.add_argument("--threads", type=int, default=None, help="threads of the strategies comparison (default 1)")
    p.add_argument("--many-threads", type=int, default=2, help="threads of the threads comparison's first arm")
    args = p.parse_args()
    if args.compare == "threads":
        check_cores(args.many_threads)
    torch.set_flush_denormal(True)  # as nnfmu.training.train does (see session.flush_denormals)
    g = torch.Generator().manual_seed(0)
    un = torch.randn(N_TRAJ, N_STEPS, N_U, generator=g)
    yn = torch.randn(N_TRAJ, N_STEPS, N_Y, generator=g)
    print(f"valve paper shape {N_TRAJ} x {N_STEPS}, n_u={N_U}, n_y={N_Y}, hidden {args.hidden}; trajectory-steps "
          f"per CPU-second (wall-clock rate in brackets), forward + backward + AdamW, median of {args.repeats} "
          "interleaved runs")
    for arch in args.archs:
        torch.manual_seed(0)
        model = build_model(ModelConfig(arch=arch, n_u=N_U, n_y=N_Y, hidden=args.hidden))
        for batch in args.batch_sizes:
            n_batches = max(1, min(args.batches, N_TRAJ // batch))
            rates = measure(variants(args.compare, model, args.threads, args.many_threads), model, un, yn, batch,
                            n_batches, args.repeats)
            names = list(rates)
            for name in names:
                each = ", ".join(f"{r:.0f}" for r in rates[name][2])
                print(f"{arch:>4s} batch {batch:4d} {name:<32s} {rates[name][0]:10.0f} /CPU-s  "
                      f"({rates[name][1]:9.0f} /s wall; each run /CPU-s: {each})")
            base = rates[names[0]]
            print(f"{'':14s} ratio {names[-1]} / {names[0]}: {rates[names[-1]][0] / base[0]:.2f} per CPU-second, "
                  f"{rates[names[-1]][1] / base[1]:.2f} wall")


if __name__ == "__main__":
    main()
