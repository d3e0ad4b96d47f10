"""Milliseconds per free run, forward and backward, of a recurrent network on a linear path: torch against C.

A training batch of ``--batch`` x ``--steps`` samples through a GRU of ``--hidden`` units on a linear path of
``--order`` states (``ModelConfig.linear_order``; a random stable A, nonzero G and alpha), float32 as the trainer
runs it, one thread. Two paths of the same model, same numbers:

- ``torch``: the generic loop over ``LinearPathStepModel.step_norm`` (``model.rollout_normalised``);
- ``compiled``: :func:`nnfmu.training.compiled_rollout.compiled_rollout` (rollout.c with the path).

Process CPU time, interleaved rounds of back-to-back calls, median printed with the ratio. Pin it to one core on
a shared machine::

    taskset -c 0 python benchmarks/linear_path_rollout.py [--batch 4] [--steps 400] [--hidden 32] [--order 4]
"""

from __future__ import annotations

import argparse
import statistics
import time

import torch

from nnfmu.models import ModelConfig, build_model
from nnfmu.training.compiled_rollout import compiled_rollout


def model_and_batch(batch: int, steps: int, hidden: int, order: int, dtype: torch.dtype):
    torch.manual_seed(0)
    model = build_model(ModelConfig(arch="gru", n_u=2, n_y=2, hidden=hidden, linear_order=order)).to(dtype).train()
    with torch.no_grad():
        A = torch.randn(order, order)
        model.lin_A.copy_(0.9 * A / torch.linalg.eigvals(A).abs().max())
        for name in ("lin_B", "lin_C", "lin_Ky", "lin_Ku", "lin_G"):
            getattr(model, name).copy_(0.3 * torch.randn(getattr(model, name).shape))
        model.alpha.fill_(0.2)
    un = torch.randn(batch, steps, 2, dtype=dtype)
    yn0 = torch.randn(batch, 2, dtype=dtype)
    return model, un, yn0


def cpu_ms(fn, un, yn0, model) -> float:
    start = time.process_time()
    loss = fn(un, yn0).square().mean()
    loss.backward()
    model.zero_grad(set_to_none=True)
    return 1e3 * (time.process_time() - start)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--batch", type=int, default=4)
    parser.add_argument("--steps", type=int, default=400)
    parser.add_argument("--hidden", type=int, default=32)
    parser.add_argument("--order", type=int, default=4)
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--float64", action="store_true")
    args = parser.parse_args()
    torch.set_num_threads(1)
    model, un, yn0 = model_and_batch(args.batch, args.steps, args.hidden, args.order,
                                     torch.float64 if args.float64 else torch.float32)
    paths = {"torch": model.rollout_normalised, "compiled": compiled_rollout(model)}
    assert paths["compiled"] is not None, "the compiled path does not apply"
    times = {name: [] for name in paths}
    for _ in range(args.rounds):  # interleaved rounds of back-to-back calls, as a training runs them
        for name, fn in paths.items():
            cpu_ms(fn, un, yn0, model)  # the first call after the other path refills the caches: not counted
            times[name] += [cpu_ms(fn, un, yn0, model) for _ in range(args.repeats)]
    med = {name: statistics.median(t) for name, t in times.items()}
    for name, value in med.items():
        print(f"{name:9s} {value:9.2f} ms per forward+backward (median of {len(times[name])})")
    print(f"speed-up  {med['torch'] / med['compiled']:.1f}x")


if __name__ == "__main__":
    main()
