"""The paper's main result at an equal budget: parallel vs series-parallel training, free-run test NRMSE.

Generates valve data (or loads a dataset folder), trains the same network
with both strategies, identical hyperparameters, epochs and seed, and prints
the free-run (float64) test NRMSE of each and their ratio. Not part of the test run.

    python benchmarks/compare_strategies.py --size paper --arch gru --hidden 32 --epochs 30
"""

from __future__ import annotations

import argparse
import time

import numpy as np
import torch

from nnfmu.data import Dataset, Trajectories, load_dataset
from nnfmu.models import ModelConfig
from nnfmu.physics import generate_dataset
from nnfmu.training import TrainConfig, train


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--data", help="dataset folder (default: generate valve data of --size)")
    p.add_argument("--size", default="paper", help="valve size to generate (small, paper)")
    p.add_argument("--arch", default="gru")
    p.add_argument("--hidden", type=int, default=32)
    p.add_argument("--epochs", type=int, default=30)
    p.add_argument("--batch-size", type=int, default=64)
    p.add_argument("--lr", type=float, default=3e-3)
    p.add_argument("--truncate", type=int, default=None)
    p.add_argument("--max-minutes", type=float, default=None, help="budget per strategy")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--threads", type=int, default=None)
    p.add_argument("--noise", type=float, default=0.0,
                   help="add white measurement noise of this fraction of each output's std to every split")
    p.add_argument("--strategies", default="parallel,series-parallel")
    args = p.parse_args()
    if args.threads:
        torch.set_num_threads(args.threads)
    t0 = time.perf_counter()
    ds = load_dataset(args.data) if args.data else generate_dataset("valve", size=args.size, seed=args.seed)
    if args.noise > 0:
        ds = with_measurement_noise(ds, args.noise, args.seed)
    print(f"data ready in {time.perf_counter() - t0:.1f} s (noise {args.noise:g} std)\n{ds.summary()}")
    model_config = ModelConfig(arch=args.arch, n_u=ds.n_u, n_y=ds.n_y, hidden=args.hidden)
    scores = {}
    for strategy in args.strategies.split(","):
        cfg = TrainConfig(strategy=strategy, epochs=args.epochs, batch_size=args.batch_size, lr=args.lr,
                          truncate=args.truncate, max_minutes=args.max_minutes, seed=args.seed)
        t0 = time.perf_counter()
        result = train(ds, model_config, cfg)
        seconds = time.perf_counter() - t0
        scores[strategy] = result.test_nrmse
        print(f"{strategy:>15s}: test free-run NRMSE {result.test_nrmse:.4f} "
              f"(per output {result.test.output_mean.round(4).tolist()}), best epoch {result.best_epoch}/"
              f"{len(result.history) - 1}, valid {result.best_valid_nrmse:.4f}, {seconds:.0f} s, "
              f"stop: {result.stop_reason}")
    if len(scores) == 2:
        print(f"ratio series-parallel / parallel test NRMSE: {scores['series-parallel'] / scores['parallel']:.2f}")


def with_measurement_noise(ds: Dataset, fraction: float, seed: int) -> Dataset:
    """``ds`` with white Gaussian noise of ``fraction`` x (train std of each output) added to every y."""
    std = fraction * ds.norm_stats("train").y_std
    rng = np.random.default_rng([seed, 12345])
    splits = {name: Trajectories(tr.u, tuple(y + rng.normal(size=y.shape) * std for y in tr.y))
              for name, tr in ds.splits.items()}
    return ds.replace(splits=splits, source={**ds.source, "measurement_noise_fraction": fraction})


if __name__ == "__main__":
    main()
