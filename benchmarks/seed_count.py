"""Issue 38: would the defaults keep a better model from more seeds? Measured one level down.

``nnfmu train`` trains one seed per core (2 on a 2-core machine) and keeps them by ``--keep select``: the seed best
on validation, joined by another only where their ensemble lowers the validation NRMSE by 1 %. Most cells stop
early, well inside the plan's 10 minutes, so a second wave of seeds would fit in the time. Whether more seeds help,
or only give the choice more lucky draws, is decided without the test split, as ``search_selection.py`` does:

- the dataset's validation split stands in for the test (the *outer* validation; one free run where the records are
  consecutive pieces, as the robot's test is one record);
- ``nnfmu train --data inner --arch A --seeds N`` runs as a user runs it, on the training split alone with its own
  inner validation, the outer validation as the inner dataset's test split (so it validates as on the whole data);
- the N seeds are cut into groups of K consecutive seeds (K = 1, 2, 4, ..., N), and each group is kept by the rule
  (``--keep select`` on the inner validation); each kept model is scored on the outer validation (free run from
  y0, float64). A K's figure is the geometric mean over its groups, so K = 2 averages N/2 draws, K = N one.
- ``all K averaged`` is the ensemble of every seed of the group (``--keep ensemble`` without its start check);
- ``cross-checked`` is a rule measured and not adopted (docs/accuracy.md): the greedy selection or that average,
  whichever scores lower on the halves of the inner validation, each rule chosen on one half and scored on the
  other (``cross_check``); its column says which it kept in each group.

The test split is not read. It prints every seed's inner and outer NRMSE, their Spearman correlation, and the
table of K. The seeds are kept in ``--work`` (the same call continues them). Not part of the tests.

    python benchmarks/seed_count.py data/valve data/robot --archs gru tcn --seeds 8 --work /tmp/seeds
"""

from __future__ import annotations

import argparse
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import torch
from scipy.stats import spearmanr
from search_selection import split  # benchmarks/search_selection.py

from nnfmu.data import load_dataset, save_dataset
from nnfmu.models import load_checkpoint, model_from_checkpoint
from nnfmu.training import TrainConfig
from nnfmu.training.ensemble import seed_paths
from nnfmu.training.ensemble_select import cross_check, ensemble_score, select_ensemble
from nnfmu.training.evaluate import score
from nnfmu.training.horizons import validation_trajectories
from nnfmu.training.trainer import prepare_dataset


def train_seeds_cli(inner_dir: Path, arch: str, seeds: int, out: Path) -> None:
    """``nnfmu train --data inner --arch arch --seeds N -o out``, as a user types it (continues a stopped run)."""
    if out.exists():
        return
    cmd = [sys.executable, "-m", "nnfmu", "train", "--data", str(inner_dir), "--arch", arch, "--seeds", str(seeds),
           "-o", str(out), "--quiet"]
    subprocess.run(cmd, check=True)


def kept(models: list, inner: list, valid, context: int, group: list) -> object:
    """The model ``--keep select`` keeps from the seeds ``group`` (indices; the caller leaves out those that never
    improved on their start, as the rule does): best on the inner validation first, joined greedily."""
    pool = sorted(group, key=lambda i: inner[i])
    return select_ensemble([models[i] for i in pool], valid, context=context, max_members=len(pool)).model


def compare(path: Path, archs: list, n: int, work: Path) -> None:
    inner_ds, outer = split(load_dataset(path))
    work = work / path.name
    inner_dir = work / "inner"
    if not inner_dir.exists():
        save_dataset(inner_ds, inner_dir)
    for arch in archs:
        out = work / f"{arch}.pt"
        train_seeds_cli(inner_dir, arch, n, out)
        summary = load_checkpoint(out)["summary"]
        cfg = TrainConfig.from_dict(load_checkpoint(seed_paths(out, [0])[0])["train_config"])
        prepared, _ = prepare_dataset(load_dataset(inner_dir), cfg)
        valid, _ = validation_trajectories(prepared, cfg)
        rows = summary["seeds"]
        ckpts = [load_checkpoint(r["checkpoint"]) for r in rows]
        models = [model_from_checkpoint(c).eval() for c in ckpts]
        context = models[0].config.init_window
        inner = [r["best_valid_nrmse"] for r in rows]
        with torch.no_grad():
            outer_of = [score(m, outer, float64=True, context=context) for m in models]
        improved = [i for i, c in enumerate(ckpts) if (c.get("best_epoch") or 0) > 0]
        rho = spearmanr(inner, outer_of).statistic
        print(f"\n## {path.name}, {arch}: {n} seeds, Spearman (inner, outer) {rho:.3f}")
        print("seeds (inner / outer): " + ", ".join(f"{r['seed']}: {a:.4f} / {b:.4f}"
                                                   for r, a, b in zip(rows, inner, outer_of)))
        print("| seeds a group (K) | groups | select: outer valid (geometric mean) | select: members | "
              "all K averaged: outer valid | cross-checked: outer valid | cross-checked kept |")
        print("|---:|---:|---:|---|---:|---:|---|")
        k = 1
        while k <= n:
            groups = [list(range(g, g + k)) for g in range(0, n - k + 1, k)]
            sel, avg, checked, sizes, which = [], [], [], [], []
            with torch.no_grad():
                for g in groups:
                    pool = [i for i in g if i in improved] or g
                    model = kept(models, inner, valid, context, pool)
                    sel.append(score(model, outer, float64=True, context=context))
                    sizes.append(len(getattr(model, "members", [model])))
                    avg.append(score(ensemble_score([models[i] for i in pool], valid, context)[0], outer,
                                     float64=True, context=context))
                    check = cross_check([models[i] for i in pool], valid, context=context)
                    averages = check is not None and check.averages
                    checked.append(avg[-1] if averages else sel[-1])
                    which.append("average" if averages else "select")
            gm = lambda xs: math.exp(np.mean(np.log(xs)))  # noqa: E731
            print(f"| {k} | {len(groups)} | {gm(sel):.4f} | {', '.join(map(str, sizes))} | {gm(avg):.4f} | "
                  f"{gm(checked):.4f} | {', '.join(which)} |", flush=True)
            k *= 2


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("datasets", nargs="+", type=Path)
    p.add_argument("--archs", nargs="+", default=["gru", "tcn"])
    p.add_argument("--seeds", type=int, default=8, help="seeds an architecture (default 8)")
    p.add_argument("--work", type=Path, required=True, help="a folder for the seeds (the same call continues)")
    args = p.parse_args()
    for path in args.datasets:
        compare(path, args.archs, args.seeds, args.work)


if __name__ == "__main__":
    main()
