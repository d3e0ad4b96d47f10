"""Issue 38: would a final refit of a network on training + validation data, for the chosen number of steps, help?

``nnfmu train`` stops on its validation split and keeps the best epoch's weights; the validation data never
trains the network. A refit would train the same network once more, from the same seed, on the training and the
validation data together, for the number of epochs (optimiser steps) the first run chose, and keep those final
weights. Whether that helps must be decided without the test split, so this script plays the choice one level
down, as ``benchmarks/linear_refit.py`` does for the linear model:

- the dataset's validation split (its own, or the tail ``nnfmu train`` cuts from one record) stands in for the test;
- an inner validation is carved from the training split the way ``nnfmu train`` carves it (the plan's tail);
- run A trains the architecture at its planned defaults (linear path, windows, batch, step budget) and keeps its
  best epoch on the inner validation; run B trains from the same seed on the whole training split for exactly the
  epochs run A kept, and keeps its final weights;
- both are scored on the outer validation (free run from y0, float64). The test split is not read.

One seed per run, ``--seeds`` repeats it (seeds 0, 1, ...). The time budget of run A is ``--minutes`` (the plan's
step budget binds first on small data); run B's budget is as much longer as its data, so its epochs bind.
``--variants`` refits in other ways too, each from the same run A (:func:`refit`), and prints each one's geometric
mean of refit / no refit over the seeds. Not part of the tests.

    python benchmarks/network_refit.py data/slider data/valve --arch gru --seeds 2 --minutes 5 --variants ema last
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

from nnfmu.data import load_dataset
from nnfmu.linear import LinearConfig, identify_linear
from nnfmu.metrics import nrmse
from nnfmu.models import architectures
from nnfmu.training import TrainConfig, train
from nnfmu.training.plan import plan_training, valid_fraction
from nnfmu.training.refit import refit_config, refit_dataset, training_and_validation
from nnfmu.training.trainer import prepare_dataset


def outer_split(ds):
    """``(dataset whose 'valid' split stands in for the test, without a test split)``: its own, or the tail."""
    if ds.valid is None:
        frac = valid_fraction(ds) if ds.train.n_traj == 1 else 0.1
        ds = ds.with_validation(frac)
    return ds.replace(splits={k: v for k, v in ds.splits.items() if k != "test"})


def inner_plan(inner, arch: str, seed: int, minutes: float):
    """The defaults ``nnfmu train --arch arch`` plans for ``inner`` (no valid split): carved dataset, configs."""
    record = architectures.architecture(arch)
    cfg = TrainConfig(strategy=record.strategies[0], dtype=record.dtype, seed=seed)
    if (frac := valid_fraction(inner)) is not None:
        cfg = cfg.replace(valid_fraction=frac)
    carved, _ = prepare_dataset(inner, cfg)
    whole = inner.train if inner.train.n_traj == 1 else None
    linear = identify_linear(carved, LinearConfig(), refit_on=whole)
    model_config = record.get("config_class")(arch=arch, n_u=inner.n_u, n_y=inner.n_y, linear_order=linear.n_x)
    plan = plan_training(inner, {"valid_fraction": cfg.valid_fraction}, linear=linear)
    cfg = cfg.replace(**{**plan.changes, "max_minutes": minutes})
    return carved, model_config, cfg, linear


VARIANTS = ("ema", "last")


def refit(carved, inner, model_config, cfg, linear, epochs: int, variant: str = "ema"):
    """Run B, as ``nnfmu train --refit`` runs it (:mod:`nnfmu.training.refit`): the same network from the same seed
    on the whole training split for ``epochs``, landing on an exponential moving average of its weights.

    ``variant``: 'ema' (the refit as built); 'last' (the last epoch's weights, not averaged, as first measured).
    """
    whole = training_and_validation(inner)
    stretch = whole.n_samples / carved.train.n_samples
    run = refit_config(cfg, cfg.seed, epochs, stretch)
    if variant == "last":
        run = run.replace(average=cfg.average)
    return train(refit_dataset(carved, whole), model_config, run, linear=linear, device="cpu").model


def outer_score(model, split) -> float:
    return nrmse(list(split.y), [model.simulate(u, y[0]) for u, y in zip(split.u, split.y)]).mean


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("datasets", nargs="+", type=Path)
    p.add_argument("--arch", default="gru")
    p.add_argument("--seeds", type=int, default=2)
    p.add_argument("--first-seed", type=int, default=0, help="the first seed (default 0)")
    p.add_argument("--minutes", type=float, default=5.0, help="time budget of run A (default 5)")
    p.add_argument("--variants", nargs="+", choices=VARIANTS, default=["ema"],
                   help="how run B refits, one column each from the same run A (see refit(); default: ema, as "
                        "nnfmu train --refit does)")
    args = p.parse_args()
    names = [f"refit, {v}" for v in args.variants]
    print(f"| dataset | seed | epochs kept | outer validation, no refit | {' | '.join(names)} | CPU s |")
    print("|---|---:|---:|---:|" + "---:|" * len(names) + "---:|")
    for path in args.datasets:
        outer = outer_split(load_dataset(path))
        inner = outer.replace(splits={k: v for k, v in outer.splits.items() if k != "valid"})
        ratios = {v: [] for v in args.variants}
        for seed in range(args.first_seed, args.first_seed + args.seeds):
            t0 = time.process_time()
            carved, model_config, cfg, linear = inner_plan(inner, args.arch, seed, args.minutes)
            first = train(carved, model_config, cfg, linear=linear, device="cpu")
            plain = outer_score(first.model, outer.valid)
            scores = []
            for v in args.variants:
                scores.append(outer_score(refit(carved, inner, model_config, cfg, linear, first.best_epoch, v),
                                          outer.valid))
                ratios[v].append(scores[-1] / plain)
            print(f"| {path.name} | {seed} | {first.best_epoch} | {plain:.4f} | "
                  f"{' | '.join(f'{x:.4f}' for x in scores)} | {time.process_time() - t0:.0f} |", flush=True)
        for v in args.variants:
            r = np.array(ratios[v])
            print(f"{path.name}: refit {v}: better on the outer validation for {int(np.sum(r < 1))} of {len(r)} seeds; "
                  f"geometric mean of refit / no refit {np.exp(np.mean(np.log(r))):.3f}", flush=True)


if __name__ == "__main__":
    main()
