"""Training throughput in trajectory-steps per second, parallel vs series-parallel, on the valve paper shape.

The paper's valve data: 900 training trajectories of 500 steps, 2 inputs, 2
outputs. One "trajectory-step" is one sample of one trajectory through the
forward pass, the backward pass and the AdamW update. The data here are random
(throughput does not depend on the values). Printed per architecture and batch
size: both strategies and their ratio. With ``--variants`` the GRU's parallel
rollout is also timed as TorchScript and with ``torch.compile`` of the cell
step, to check whether either is worth using (timings on a shared machine are
noisy: the minimum of ``--repeats`` runs is printed).

    python benchmarks/train_throughput.py --archs gru --hidden 64 --batch-sizes 64 900 --variants
"""

from __future__ import annotations

import argparse
import time

import torch
from torch.nn import functional as F

from nnfmu.models import ModelConfig, build_model
from nnfmu.training.batches import masked_mse

N_TRAJ, N_STEPS, N_U, N_Y = 900, 500, 2, 2


def time_updates(rollout, model, un, yn, batch: int, n_batches: int, repeats: int) -> float:
    """Best trajectory-steps/s of ``n_batches`` optimiser steps of ``rollout(un_b, yn_b) -> pred``."""
    opt = torch.optim.AdamW(model.parameters(), lr=1e-3)
    best = float("inf")
    for _ in range(repeats):
        t0 = time.perf_counter()
        for b in range(n_batches):
            idx = slice(b * batch, (b + 1) * batch)
            loss = masked_mse(rollout(un[idx], yn[idx]), yn[idx], None)
            opt.zero_grad(set_to_none=True)
            loss.backward()
            torch.nn.utils.clip_grad_norm_(model.parameters(), 1.0)
            opt.step()
        best = min(best, time.perf_counter() - t0)
    return n_batches * batch * N_STEPS / best


def scripted_gru_rollout():
    """The GRU free run (one layer, skip) as one TorchScript function: the loop runs without Python."""

    def rollout(un: torch.Tensor, yn0: torch.Tensor, w_ih: torch.Tensor, w_hh: torch.Tensor, b_ih: torch.Tensor,
                b_hh: torch.Tensor, w_out: torch.Tensor, b_out: torch.Tensor, scale: float) -> torch.Tensor:
        h = torch.zeros(un.shape[0], w_hh.shape[1], dtype=un.dtype)
        yn = yn0
        ys = [yn0]
        for k in range(un.shape[1] - 1):
            h = torch.gru_cell(torch.cat([yn, un[:, k]], 1), h, w_ih, w_hh, b_ih, b_hh)
            yn = yn + scale * F.linear(h, w_out, b_out)
            ys.append(yn)
        return torch.stack(ys, 1)

    return torch.jit.script(rollout)


def variants(model, un, yn, batch, n_batches, repeats) -> dict:
    """Parallel GRU rollout: eager (the model), TorchScript of the loop, torch.compile of the cell step."""
    out = {"eager": time_updates(lambda u, y: model.rollout_normalised(u, y[:, 0]), model, un, yn,
                                 batch, n_batches, repeats)}
    layer = model.rnn_layers[0]
    script = scripted_gru_rollout()
    weights = lambda: (layer.weight_ih_l0, layer.weight_hh_l0, layer.bias_ih_l0, layer.bias_hh_l0,  # noqa: E731
                       model.readout.weight, model.readout.bias, model.config.skip_scale)
    out["torchscript"] = time_updates(lambda u, y: script(u, y[:, 0], *weights()), model, un, yn,
                                      batch, n_batches, repeats)
    eager_step = model._cell_step
    t0 = time.perf_counter()
    model._cell_step = torch.compile(eager_step, dynamic=False)
    try:
        model.rollout_normalised(un[:batch], yn[:batch, 0]).sum().backward()  # compile outside the timing
        compile_s = time.perf_counter() - t0
        out[f"torch.compile (compiled in {compile_s:.0f} s)"] = time_updates(
            lambda u, y: model.rollout_normalised(u, y[:, 0]), model, un, yn, batch, n_batches, repeats)
    except Exception as exc:  # report, do not abort the benchmark
        out[f"torch.compile failed: {type(exc).__name__}"] = float("nan")
    finally:
        model._cell_step = eager_step
    return out


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--archs", nargs="+", default=["gru"])
    p.add_argument("--hidden", type=int, default=64)
    p.add_argument("--batch-sizes", nargs="+", type=int, default=[64, 900])
    p.add_argument("--batches", type=int, default=2, help="optimiser steps timed per run")
    p.add_argument("--repeats", type=int, default=3)
    p.add_argument("--threads", type=int, default=None)
    p.add_argument("--keep-denormals", action="store_true",
                   help="do not flush denormals to zero (shows how slow backpropagation through long rollouts gets)")
    p.add_argument("--variants", action="store_true", help="also time TorchScript and torch.compile (GRU)")
    args = p.parse_args()
    if args.threads:
        torch.set_num_threads(args.threads)
    if not args.keep_denormals:
        torch.set_flush_denormal(True)  # as nnfmu.training.train does (see session.flush_denormals)
    g = torch.Generator().manual_seed(0)
    un = torch.randn(N_TRAJ, N_STEPS, N_U, generator=g)
    yn = torch.randn(N_TRAJ, N_STEPS, N_Y, generator=g)
    denormals = "kept" if args.keep_denormals else "flushed"
    print(f"valve paper shape {N_TRAJ} x {N_STEPS}, n_u={N_U}, n_y={N_Y}, hidden {args.hidden}, "
          f"{torch.get_num_threads()} threads, denormals {denormals}; trajectory-steps/s "
          f"(forward + backward + AdamW), best of {args.repeats}")
    for arch in args.archs:
        torch.manual_seed(0)
        model = build_model(ModelConfig(arch=arch, n_u=N_U, n_y=N_Y, hidden=args.hidden))
        for batch in args.batch_sizes:
            n_batches = max(1, min(args.batches, N_TRAJ // batch))
            par = time_updates(lambda u, y: model.rollout_normalised(u, y[:, 0]), model, un, yn, batch,
                               n_batches, args.repeats)
            ser = time_updates(lambda u, y: model.rollout_normalised(u, y[:, 0], y), model, un, yn, batch,
                               n_batches, args.repeats)
            epoch = N_TRAJ * N_STEPS
            print(f"{arch:>4s} batch {batch:4d}: parallel {par:10.0f} ({epoch / par:5.2f} s/epoch)   "
                  f"series-parallel {ser:10.0f} ({epoch / ser:5.2f} s/epoch)   ratio sp/p {ser / par:5.2f}")
            if args.variants and arch == "gru":
                for name, rate in variants(model, un, yn, batch, n_batches, args.repeats).items():
                    print(f"      parallel {name:<40s} {rate:10.0f} ({epoch / rate:5.2f} s/epoch)")


if __name__ == "__main__":
    main()
