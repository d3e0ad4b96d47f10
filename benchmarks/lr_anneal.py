"""Does ``--lr-schedule anneal`` carry beyond the validation that chose it? Measured one level down.

``anneal`` trains at the constant rate until the patience runs out, then goes on from the best weights at a tenth
of the rate, and at a hundredth (:mod:`nnfmu.training.lr_plateau`). Its constant stage *is* the constant schedule's
run, so on the validation it follows it can only be better; the question is whether that gain is real or a
choice among more noisy epochs. As ``benchmarks/network_refit.py`` does for a refit:

- the dataset's validation split (its own, or the tail ``nnfmu train`` cuts from one record) stands in for the test;
- an inner validation is carved from the training split the way ``nnfmu train`` carves it, and the architecture
  trains at its planned defaults (linear path, windows, batch, step budget) with ``lr_schedule='anneal'``;
- the best weights when the constant stage ended (what ``lr_schedule='constant'`` keeps, epoch for epoch the same
  run) and the best weights at the end are both scored on the outer validation (free run from y0, float64).

The test split is not read. One seed per run; ``--seeds`` repeats it (seeds 0, 1, ...). Not part of the tests.

    python benchmarks/lr_anneal.py data/slider data/valve --arch gru --seeds 2
"""

from __future__ import annotations

import argparse
import copy
import math
import time
from pathlib import Path

from network_refit import inner_plan, outer_score, outer_split

from nnfmu.data import load_dataset
from nnfmu.training import train
from nnfmu.training.trainer import _new_model


def annealed(carved, model_config, cfg, linear):
    """One ``anneal`` training; (model at its best, the constant stage's best state, inner scores, epochs)."""
    model = _new_model(model_config, carved, cfg, linear)
    # the best state so far, and the best score as of the previous epoch (epoch 0's included, which no callback sees)
    seen = {"state": copy.deepcopy(model.state_dict()), "constant": None, "best": math.inf, "epochs": 0}

    def at_epoch(epoch, entry):
        if seen["constant"] is None and entry["lr_factor"] < 1.0:  # the first epoch of the second stage
            seen["constant"], seen["constant_score"], seen["epochs"] = seen["state"], seen["best"], epoch - 1
        if entry["improved"]:
            seen["state"] = copy.deepcopy(model.state_dict())
        seen["best"] = entry["best_valid_nrmse"]

    result = train(carved, model, cfg.replace(lr_schedule="anneal"), callback=at_epoch, device="cpu")
    if seen["constant"] is None:  # the constant stage ended the run (its epochs or time): anneal changed nothing
        seen["constant"], seen["constant_score"] = seen["state"], result.best_valid_nrmse
        seen["epochs"] = len(result.history) - 1
    return result, seen


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("datasets", nargs="+", type=Path)
    p.add_argument("--arch", default="gru")
    p.add_argument("--seeds", type=int, default=2)
    p.add_argument("--minutes", type=float, default=10.0, help="time budget of each training (default 10)")
    args = p.parse_args()
    print("| dataset | arch | seed | epochs: constant stage, all | inner validation: constant, anneal | "
          "outer validation: constant, anneal | CPU s |")
    print("|---|---|---:|---|---|---|---:|")
    ratios = []
    for path in args.datasets:
        outer = outer_split(load_dataset(path))
        inner = outer.replace(splits={k: v for k, v in outer.splits.items() if k != "valid"})
        for seed in range(args.seeds):
            t0 = time.process_time()
            carved, model_config, cfg, linear = inner_plan(inner, args.arch, seed, args.minutes)
            result, seen = annealed(carved, model_config, cfg, linear)
            after = outer_score(result.model, outer.valid)
            result.model.load_state_dict(seen["constant"])
            before = outer_score(result.model.eval(), outer.valid)
            ratios.append(after / before)
            print(f"| {path.name} | {args.arch} | {seed} | {seen['epochs']}, {len(result.history) - 1} | "
                  f"{seen['constant_score']:.4f}, {result.best_valid_nrmse:.4f} | {before:.4f}, {after:.4f} | "
                  f"{time.process_time() - t0:.0f} |", flush=True)
    better = sum(r < 1.0 for r in ratios)
    mean = math.exp(sum(map(math.log, ratios)) / len(ratios))
    print(f"\nanneal against constant on the outer validation: better in {better} of {len(ratios)}, equal in "
          f"{sum(r == 1.0 for r in ratios)}; geometric mean of the ratios {mean:.4f}")


if __name__ == "__main__":
    main()
