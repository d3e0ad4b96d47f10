"""Milliseconds per hybrid step, forward and backward: stage by stage against the whole step as one compiled call.

A training rollout of a hybrid (physics ODE + correction network inside every RK4 stage)
over windows of ``--steps`` samples at ``--batch``, forward then backward, as the trainer
runs it (float64, one thread). Two paths of the same model, same numbers:

- ``per-stage``: one compiled ODE call per RK4 stage and the network in torch (before);
- ``fused``: the whole step, every stage with the network, as one compiled call forward and
  one backward (:mod:`nnfmu.hybrid.fused`, the default where it applies).

Process CPU time, interleaved repeats, median printed with the ratio of the same run. Pin it
to one core on a shared machine::

    taskset -c 1 python benchmarks/hybrid_step.py [--physics valve arm] [--batch 36] [--steps 100]
"""

from __future__ import annotations

import argparse
import os
import statistics
import time

import numpy as np
import torch

from nnfmu.hybrid import HybridConfig
from nnfmu.models import build_model
from nnfmu.training.compiled_rollout import ENV_SWITCH

ARM_Y0 = np.array([10.0, -30.0, 40.0, 5.0, -20.0, 15.0])


def model_and_batch(physics: str, batch: int, steps: int, hidden: int, backend: str = "compiled"):
    """A float64 hybrid with a nonzero correction; normalised inputs and initial outputs near its operating point."""
    n = {"valve": 2, "arm": 6}[physics]
    config = HybridConfig(n_u=n, n_y=n, physics=physics, hidden=hidden, physics_backend=backend)
    model = build_model(config).double().train()
    g = torch.Generator().manual_seed(0)
    with torch.no_grad():
        for prm in model.correction.parameters():
            prm.copy_(0.1 * torch.randn(prm.shape, generator=g, dtype=torch.float64))
    if physics == "valve":
        u = 100.0 + 20.0 * torch.rand(batch, steps, n, generator=g, dtype=torch.float64)
        y0 = torch.tensor([5e-4, 3e5], dtype=torch.float64).repeat(batch, 1)
    else:
        u = 5.0 * (2 * torch.rand(batch, steps, n, generator=g, dtype=torch.float64) - 1)
        y0 = torch.tensor(ARM_Y0).repeat(batch, 1)
    return model, model.normalise_u(u), model.normalise_y(y0)


def forward_backward(model, un, yn0) -> tuple[float, float]:
    """CPU seconds of one rollout forward, and of its backward pass."""
    c0 = time.process_time()
    ys = model.rollout_normalised(un, yn0)
    c1 = time.process_time()
    ys.square().mean().backward()
    return c1 - c0, time.process_time() - c1


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--physics", nargs="+", default=["valve"], choices=["valve", "arm"],
                   help="the arm keeps the per-stage path (nnfmu.hybrid.fused.MAX_ODE_INSTRUCTIONS): both rows equal")
    p.add_argument("--batch", type=int, default=36, help="trajectories per rollout (hybrid_valve.py trains at 36)")
    p.add_argument("--steps", type=int, default=100, help="samples per window")
    p.add_argument("--hidden", type=int, default=32)
    p.add_argument("--repeats", type=int, default=5)
    args = p.parse_args()
    torch.set_num_threads(1)
    print(f"ms per step of a batch of {args.batch} trajectories, median of {args.repeats} interleaved rollouts of "
          f"{args.steps} steps, float64, process CPU time")
    for physics in args.physics:
        model, un, yn0 = model_and_batch(physics, args.batch, args.steps, args.hidden)
        times = {"per-stage": [], "fused": []}
        for name, switch in (("per-stage", "0"), ("fused", "1")):  # warm-up: compile and load once
            os.environ[ENV_SWITCH] = switch
            forward_backward(model, un[:, :3], yn0)
        for _ in range(args.repeats):
            for name, switch in (("per-stage", "0"), ("fused", "1")):
                os.environ[ENV_SWITCH] = switch
                times[name].append(forward_backward(model, un, yn0))
        os.environ.pop(ENV_SWITCH)
        per_step = {k: [(f + b) * 1e3 / (args.steps - 1) for f, b in v] for k, v in times.items()}
        for name, values in times.items():
            fwd = statistics.median(f for f, _ in values) * 1e3 / (args.steps - 1)
            bwd = statistics.median(b for _, b in values) * 1e3 / (args.steps - 1)
            print(f"  {physics:5s} {name:9s} forward {fwd:7.3f}  backward {bwd:7.3f}  total "
                  f"{statistics.median(per_step[name]):7.3f} ms per step")
        ratio = statistics.median(per_step["per-stage"]) / statistics.median(per_step["fused"])
        print(f"  {physics:5s} fused is {ratio:.1f}x faster per step (forward + backward)")


if __name__ == "__main__":
    main()
