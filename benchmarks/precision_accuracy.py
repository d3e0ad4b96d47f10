"""What the fast profile and float32 cost in accuracy on the valve test set (issue 14).

Each architecture is trained in parallel mode on the generated valve data (or
taken from ``--checkpoints``), exported as an ``exact``, a ``fast`` and a
``fast`` float32 FMU, and every FMU is scored the one way nnfmu scores models:
fmpy co-simulates it on the test split and :func:`nnfmu.metrics.nrmse` scores
the free run. Printed per network: the three NRMSEs, the differences against
the exact float64 FMU, and the largest output difference over the test set
relative to each output's range.

    python benchmarks/precision_accuracy.py [--size paper|small] [--archs gru lstm ...] [--hidden 32]
                                            [--epochs 20] [--max-minutes 3] [--checkpoints a.pt b.pt]
"""

from __future__ import annotations

import argparse
import tempfile
from pathlib import Path

import numpy as np

from nnfmu.cosim import evaluate
from nnfmu.export import build_fmu, casadi_model
from nnfmu.export.fmu import BuildOptions
from nnfmu.models import ModelConfig, load_model
from nnfmu.models.base import torch_threads
from nnfmu.physics import generate_dataset
from nnfmu.training import TrainConfig, train

BUILDS = {"exact": BuildOptions(profile="exact"), "fast": BuildOptions(), "fast f32": BuildOptions(precision="float32")}


def networks(args, dataset):
    """``{label: network}``: the checkpoints given, or each architecture trained here."""
    if args.checkpoints:
        return {Path(p).stem: load_model(p) for p in args.checkpoints}
    out = {}
    config = TrainConfig(strategy="parallel", truncate=100, epochs=args.epochs, max_minutes=args.max_minutes,
                         patience=args.epochs)
    for arch in args.archs:
        with torch_threads(1):
            result = train(dataset, ModelConfig(arch=arch, n_u=dataset.n_u, n_y=dataset.n_y, hidden=args.hidden),
                           config)
        out[f"{arch}{args.hidden}"] = result.model
    return out


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--size", default="paper", choices=["paper", "small"], help="generated valve data")
    parser.add_argument("--noise", type=float, default=0.05, help="measurement noise, as in the study")
    parser.add_argument("--archs", nargs="+", default=["gru", "lstm", "rnn", "mlp", "tcn"])
    parser.add_argument("--hidden", type=int, default=32)
    parser.add_argument("--epochs", type=int, default=20)
    parser.add_argument("--max-minutes", type=float, default=3.0, help="wall-clock cap of one training")
    parser.add_argument("--checkpoints", nargs="*", help="score these instead of training")
    args = parser.parse_args(argv)
    dataset = generate_dataset("valve", size=args.size, seed=0).with_measurement_noise(args.noise)
    print(f"{'network':<10}{'exact':>9}{'fast':>9}{'f32':>9}{'fast-exact':>12}{'f32-exact':>11}"
          f"{'max |dy|/range fast':>21}{'f32':>9}")
    with tempfile.TemporaryDirectory() as tmp:
        for label, network in networks(args, dataset).items():
            model = casadi_model(network)
            paths = [build_fmu(model, Path(tmp) / f"{label}_{i}.fmu", options=o) for i, o in enumerate(BUILDS.values())]
            scores = dict(zip(BUILDS, evaluate(paths, dataset)))
            exact = np.concatenate(scores["exact"].predictions)
            span = np.ptp(np.concatenate(dataset.test.y), axis=0)
            dy = {b: float((np.abs(np.concatenate(scores[b].predictions) - exact) / span).max())
                  for b in ("fast", "fast f32")}
            nrmse = {b: scores[b].result.mean for b in BUILDS}
            print(f"{label:<10}{nrmse['exact']:>9.5f}{nrmse['fast']:>9.5f}{nrmse['fast f32']:>9.5f}"
                  f"{nrmse['fast'] - nrmse['exact']:>12.1e}{nrmse['fast f32'] - nrmse['exact']:>11.1e}"
                  f"{dy['fast']:>21.1e}{dy['fast f32']:>9.1e}")


if __name__ == "__main__":
    main()
