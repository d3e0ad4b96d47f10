"""Hybrid training speed in trajectory-steps per second, forward and backward, on the CPU and on a CUDA GPU.

A hybrid valve or arm (``--physics``; derivative correction, 32 hidden, float64 as the hybrid trains) runs what the
trainer runs per batch: the free run of ``--batch`` trajectories over windows of ``--steps``
samples (inputs near the valve's operating point, as benchmarks/hybrid_step.py), then the backward
pass of the mean squared output. One trajectory-step is one sample of one trajectory, forward and
backward. Paths (the issue's "before" is the sx backend eager, on either device):

  cpu   sx, per-stage           the SX translation, one torch operation per instruction
  cpu   compiled, per-stage     the C physics, one call per RK4 stage, the network in torch
  cpu   compiled, fused         the whole step as one C call forward, one backward (the CPU default)
  cuda  sx, eager               one kernel per instruction
  cuda  sx, fused kernels       each translated function through torch.compile (nnfmu.hybrid.casadi_torch)
  cuda  sx, graphed             the whole free run recorded as CUDA graphs (nnfmu.hybrid.graphed)
  cuda  sx, fused + graphed     both (the GPU default)

The CPU rows use process CPU time on one thread (pin the process to one core on a shared machine); the
CUDA rows wall time between synchronisations. Each path's first call (compiling, recording) is timed
apart as "setup". Repeats are interleaved and the median printed, with each path's speed relative to
the first row of its device and the largest relative difference of its gradients from that row's.

    taskset -c 1 python benchmarks/hybrid_speed.py --device cpu
    python benchmarks/hybrid_speed.py --device cuda           # on a GPU machine
"""

from __future__ import annotations

import argparse
import contextlib
import os
import platform
import statistics
import sys
import time
from pathlib import Path

import torch

sys.path.insert(0, str(Path(__file__).resolve().parent))
from hybrid_step import model_and_batch  # noqa: E402  (the same model and inputs)

from nnfmu.hybrid import casadi_torch, graphed  # noqa: E402
from nnfmu.training.compiled_rollout import ENV_SWITCH  # noqa: E402


@contextlib.contextmanager
def switches(*, compiled: bool, fused_kernels: bool = False):
    """``compiled``: NNFMU_COMPILED_ROLLOUT (the CPU's fused step); ``fused_kernels``: torch.compile on CUDA."""
    old_env, old_fuses = os.environ.get(ENV_SWITCH), casadi_torch.TorchFunction._fuses
    os.environ[ENV_SWITCH] = "1" if compiled else "0"
    if not fused_kernels:
        casadi_torch.TorchFunction._fuses = lambda self, device: False
    try:
        yield
    finally:
        casadi_torch.TorchFunction._fuses = old_fuses
        if old_env is None:
            os.environ.pop(ENV_SWITCH, None)
        else:
            os.environ[ENV_SWITCH] = old_env


def paths(device: str, batch: int, steps: int, hidden: int, physics: str = "valve") -> dict:
    """name -> (model, un, yn0, free_run(un, yn0), switch settings)."""
    if device == "cpu":
        sx = model_and_batch(physics, batch, steps, hidden, backend="sx")
        compiled = model_and_batch(physics, batch, steps, hidden)
        return {"sx, per-stage": (*sx, None, {"compiled": False}),
                "compiled, per-stage": (*compiled, None, {"compiled": False}),
                "compiled, fused": (*compiled, None, {"compiled": True})}
    model, un, yn0 = (t.to(device) for t in model_and_batch(physics, batch, steps, hidden, backend="sx"))
    return {"sx, eager": (model, un, yn0, None, {"compiled": False}),
            "sx, fused kernels": (model, un, yn0, None, {"compiled": True, "fused_kernels": True}),
            "sx, graphed": (model, un, yn0, graphed.RecordedFreeRuns(), {"compiled": True}),
            "sx, fused + graphed": (model, un, yn0, graphed.RecordedFreeRuns(),
                                    {"compiled": True, "fused_kernels": True})}


def iteration(model, un, yn0, recorded, settings) -> tuple[float, list[torch.Tensor]]:
    """Seconds of one free run and backward pass (CPU: process time; CUDA: wall), and the gradients."""
    cuda = un.device.type == "cuda"
    clock = time.perf_counter if cuda else time.process_time
    with switches(**settings):
        model.zero_grad(set_to_none=True)
        if cuda:
            torch.cuda.synchronize()
        start = clock()
        ys = model.rollout_normalised(un, yn0) if recorded is None else recorded.run(model, un, yn0)
        ys.square().mean().backward()
        if cuda:
            torch.cuda.synchronize()
        seconds = clock() - start
    return seconds, [p.grad.detach().clone() for p in model.parameters() if p.grad is not None]


def relative_difference(grads: list[torch.Tensor], reference: list[torch.Tensor]) -> float:
    return max(float((g - r).abs().max() / r.abs().max().clamp_min(1e-300)) for g, r in zip(grads, reference))


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--device", default="cpu", help="cpu or cuda")
    p.add_argument("--batch", type=int, default=40, help="trajectories per batch (the small valve set has 40)")
    p.add_argument("--steps", type=int, default=50, help="samples per window")
    p.add_argument("--hidden", type=int, default=32)
    p.add_argument("--physics", default="valve", choices=["valve", "arm"],
                   help="the arm: 12 states, a 4208-instruction ODE, 50 RK4 sub-steps a sample (the CPU's fused "
                        "row equals its per-stage one: nnfmu.hybrid.fused.MAX_ODE_INSTRUCTIONS)")
    p.add_argument("--repeats", type=int, default=3)
    p.add_argument("--paths", nargs="+", metavar="PATH",
                   help="only these rows, by name (e.g. 'sx, eager' 'sx, fused + graphed'); the first is the base")
    args = p.parse_args()
    torch.set_num_threads(1)
    where = torch.cuda.get_device_name() if args.device.startswith("cuda") else platform.processor() or "cpu"
    print(f"hybrid {args.physics}, batch {args.batch} x {args.steps} steps, float64, torch {torch.__version__}, "
          f"{where}")
    table = paths(args.device, args.batch, args.steps, args.hidden, args.physics)
    if args.paths:
        unknown = sorted(set(args.paths) - set(table))
        if unknown:
            p.error(f"unknown paths {unknown}; the {args.device} paths are {list(table)}")
        table = {name: table[name] for name in args.paths}
    setup, times, grads = {}, {name: [] for name in table}, {}
    for name, path in table.items():
        setup[name], grads[name] = iteration(*path)
        print(f"  setup {name:22s} {setup[name]:8.2f} s", flush=True)
    for _ in range(args.repeats):
        for name, path in table.items():
            times[name].append(iteration(*path)[0])
    first = next(iter(table))
    base = statistics.median(times[first])
    print(f"{'path':24s} {'traj-steps/s':>13s} {'s/batch':>9s} {'speed-up':>9s} {'grad rel diff':>14s}")
    for name in table:
        t = statistics.median(times[name])
        rate = args.batch * (args.steps - 1) / t
        diff = relative_difference(grads[name], grads[first])
        print(f"{args.device:4s} {name:19s} {rate:13.0f} {t:9.3f} {base / t:8.1f}x {diff:14.1e}")


if __name__ == "__main__":
    main()
