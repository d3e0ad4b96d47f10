"""Issue 38: which model should a time-budget search keep? Selection rules compared one level down.

Every long search found its best validation score early, from a lucky seed: further seeds of the same point scored
worse, and the kept model did not carry to the test. This script decides between rules for what the search keeps
without reading the test split, as ``benchmarks/linear_refit.py`` and ``network_refit.py`` do:

- the dataset's validation split (its own, or the one ``nnfmu train`` carves) stands in for the test (the
  *outer* validation; joined end to end where the
  dataset's records are consecutive pieces of one recording, as the robot's test is one record);
- the search (``nnfmu train --max-minutes N``, as a new user runs it) runs on the training split alone, which gets
  its own *inner* validation: the last tenth of the pieces where they are consecutive (so the search joins them,
  as it does on the whole dataset), otherwise what ``nnfmu train`` carves;
- the outer validation is the inner dataset's test split, so the search validates as it does on the whole dataset
  (the robot's inner pieces joined, as its test record is longer than one piece);
- every trial's checkpoint is kept, and each rule's model is scored on the outer validation (free run from y0,
  float64). The test split is not read.

The rules, each using the inner validation only:

- ``best``: the trial with the lowest inner validation NRMSE;
- ``greedy`` (the search's rule before): from the best trial, the greedy ensemble of the 6 best trials that improved
  on their start, a member joining only where it lowers the inner NRMSE by 1 %;
- ``point mean``: the point (architecture, width, rate, noise, windows) whose seeds that trained to their own stop
  have the lowest mean inner NRMSE, among points with at least two such seeds, and the ensemble of its (up to 4)
  best seeds, every one of them, not chosen greedily;
- ``point greedy`` (the search's rule now, where a point has two seeds; it also prints what the search kept):
  the same point, its seeds joined greedily as ``greedy`` does;
- ``point in order``: the same point, the ensemble of its first (up to 4) seeds in the order they were trained,
  every one of them: no choice among the seeds at all.

It prints, per architecture, its trials, how many successive halving stopped, and its best trial; then each rule's
inner and outer NRMSE, the best trial on the outer validation (which no rule can know), trial 0 (the defaults), and
the Spearman correlation of inner against outer over the trials that trained to their own stop. ``--halving arch``
halves each architecture among its own trials (``nnfmu.study.time_search.HALVING_BY``). Not part of the tests.

    python benchmarks/search_selection.py data/valve data/robot --minutes 20 --work /tmp/sel
    python benchmarks/search_selection.py data/valve --work /tmp/sel --rescore   # the rules again, on the kept trials
    python benchmarks/search_selection.py data/robot --minutes 10 --work /tmp/sel --halving arch   # halving per arch
"""

from __future__ import annotations

import argparse
import json
import math
import time
from collections import defaultdict
from pathlib import Path

import numpy as np
import torch
from scipy.stats import spearmanr

from nnfmu.data import load_dataset, save_dataset
from nnfmu.models import load_checkpoint, model_from_checkpoint
from nnfmu.study import time_search
from nnfmu.study.time_space import point_key
from nnfmu.training.ensemble_select import ensemble_score, select_ensemble
from nnfmu.training.evaluate import score
from network_refit import outer_split  # benchmarks/network_refit.py

MAX_MEMBERS = 4


def split(ds):
    """``(inner dataset for the search, outer validation trajectories)``; neither holds the test split."""
    ds = outer_split(ds)  # its own valid split, or the one nnfmu train would carve
    outer = ds.valid.concatenated() if ds.consecutive_pieces else ds.valid
    splits = {"train": ds.train, "test": outer}  # the stand-in: the search scores its kept model on it, as on a test
    if ds.consecutive_pieces:
        n = ds.train.n_traj
        cut = n - max(1, round(0.1 * n))
        splits.update(train=ds.train.subset(list(range(cut))), valid=ds.train.subset(list(range(cut, n))))
    return ds.replace(splits=splits), outer


def run_search(inner_dir: Path, minutes: float, work: Path) -> tuple:
    """The search as ``nnfmu train --data inner --max-minutes minutes`` runs it, its trials kept in ``work/trials``."""
    from nnfmu.cli._train_plan import TrainRequest, make_plan
    from nnfmu.study.time_search import search_for

    request = TrainRequest(data=str(inner_dir), out=work / "search.pt", train_options={"max_minutes": minutes},
                           quiet=True, force=True)
    plan = make_plan(request)
    result = search_for(plan.data, minutes, model_config=plan.model_config, train_config=plan.train_config,
                        linear=plan.linear, out=plan.out, given=set(plan.given), seed=plan.train_config.seed,
                        progress=False, since=request.started, keep_trials=work / "trials")
    return plan, result


def rescored(work: Path) -> tuple:
    """``(plan, result)`` of a search run before in ``work`` (its ``rows.json``, ``trials`` and ``inner``), without
    training: ``result`` has the rows only (what the search kept and its CPU share are not known again)."""
    from types import SimpleNamespace

    from nnfmu.cli._train_plan import TrainRequest, make_plan

    rows = json.loads((work / "rows.json").read_text())
    plan = make_plan(TrainRequest(data=str(work / "inner"), out=work / "rescore.pt", quiet=True, force=True,
                                  train_options={"max_minutes": 1}))
    return plan, SimpleNamespace(rows=rows, members=None, selection=None, usage=None)


def compare(path: Path, minutes: float, work: Path, rescore: bool = False) -> None:
    ds = load_dataset(path)
    inner, outer = split(ds)
    work.mkdir(parents=True, exist_ok=True)
    t0 = time.monotonic()
    if rescore:
        plan, result = rescored(work)
    else:
        inner_dir = save_dataset(inner, work / "inner")
        plan, result = run_search(inner_dir, minutes, work)
        (work / "rows.json").write_text(json.dumps(result.rows, indent=1))  # with the trials: for later comparisons
    inner_valid = _inner_valid(plan)
    context = plan.model_config.init_window
    rows = [r for r in result.rows if r["best_valid_nrmse"] is not None]
    models, outer_of, improved = {}, {}, set()
    for r in rows:
        ckpt = load_checkpoint(work / "trials" / f"trial-{r['trial']}.pt")
        if (ckpt.get("best_epoch") or 0) > 0:
            improved.add(r["trial"])
        if r["trial"] in improved or r["trial"] == 0:
            models[r["trial"]] = model_from_checkpoint(ckpt).eval()
    with torch.no_grad():
        for i, m in models.items():
            outer_of[i] = score(m, outer, float64=True, context=context)
    full = [r for r in rows if r["trial"] in models and not r["stopped"]]
    rho = (spearmanr([r["best_valid_nrmse"] for r in full], [outer_of[r["trial"]] for r in full]).statistic
           if len(full) > 2 else math.nan)
    ranked = sorted((r for r in rows if r["trial"] in models), key=lambda r: r["best_valid_nrmse"])
    # the search's rule before: from the best trial, the 6 best that improved on their start, joined greedily
    top = [ranked[0]["trial"]] + [r["trial"] for r in ranked[1:] if r["trial"] in improved][:5]
    chosen = select_ensemble([models[i] for i in top], inner_valid, context=context).chosen
    picks = {"best": [ranked[0]["trial"]], "greedy": [top[j] for j in chosen]}
    seeds = defaultdict(list)
    for r in full:
        seeds[point_key(r)].append(r)
    multi = {k: sorted(v, key=lambda r: r["best_valid_nrmse"]) for k, v in seeds.items() if len(v) >= 2}
    if multi:
        key = min(multi, key=lambda k: np.mean([r["best_valid_nrmse"] for r in multi[k]]))
        members = [r["trial"] for r in multi[key][:MAX_MEMBERS]]
        picks["point mean"] = members
        chosen = select_ensemble([models[i] for i in members], inner_valid, context=context)
        picks["point greedy"] = [members[j] for j in chosen.chosen]
        picks["point in order"] = sorted(r["trial"] for r in multi[key])[:MAX_MEMBERS]
    share = "" if result.usage is None else f"; CPU share {100 * result.usage['cpu_share']:.0f} %"
    counts = f"{len(result.rows)} trials ({len(full)} trained to their own stop"
    head = (f"the trials kept in {work}, rescored: {counts})" if rescore else
            f"search of {minutes:g} min on the inner split, {counts}; further seeds from "
            f"{time_search.RESEED_AFTER:.2f} of the budget; halving by {time_search.HALVING_BY})")
    print(f"\n## {path.name}: {head}, {time.monotonic() - t0:.0f} s{share}")
    if multi:
        means = sorted((np.mean([r['best_valid_nrmse'] for r in v]), k, len(v)) for k, v in multi.items())
        for mean, k, n in means[:5]:
            outs = [outer_of[r["trial"]] for r in multi[k]]
            print(f"point {k}: {n} seeds, inner mean {mean:.4f}, outer mean {np.mean(outs):.4f} "
                  f"(min {min(outs):.4f}, max {max(outs):.4f})")
    print(f"Spearman (inner validation, outer validation) over {len(full)} trials: {rho:.3f}")
    for arch in dict.fromkeys(r["arch"] for r in result.rows):
        mine = [r for r in result.rows if r["arch"] == arch]
        scored = [r for r in mine if r["trial"] in models]
        best = min(scored, key=lambda r: r["best_valid_nrmse"], default=None)
        at = "" if best is None else (f"; best inner {best['best_valid_nrmse']:.4f} (trial {best['trial']}, outer "
                                      f"{outer_of[best['trial']]:.4f})")
        print(f"{arch}: {len(mine)} trials, {sum(r['stopped'] for r in mine)} stopped by successive halving, "
              f"{sum(r['epochs'] for r in mine)} epochs in all{at}")
    if result.members is not None:
        print(f"the search kept trials {', '.join(map(str, result.members))} ({result.selection})")
    print("| rule | trials | inner valid | outer valid (stands in for the test) |")
    print("|---|---|---:|---:|")
    with torch.no_grad():
        for name, members in picks.items():
            model, inner_score = ensemble_score([models[i] for i in members], inner_valid, context)
            print(f"| {name} | {', '.join(map(str, members))} | {inner_score:.4f} | "
                  f"{score(model, outer, float64=True, context=context):.4f} |", flush=True)
        kept = [i for i in result.members or () if i in models]
        if result.members and kept == list(result.members):
            model, inner_score = ensemble_score([models[i] for i in kept], inner_valid, context)
            print(f"| (what the search kept) | {', '.join(map(str, kept))} | {inner_score:.4f} | "
                  f"{score(model, outer, float64=True, context=context):.4f} |")
    oracle = min(outer_of, key=outer_of.get)
    print(f"| (trial 0, the defaults) | 0 | {rows[0]['best_valid_nrmse']:.4f} | {outer_of.get(0, math.nan):.4f} |")
    print(f"| (best trial on the outer validation) | {oracle} | "
          f"{next(r['best_valid_nrmse'] for r in rows if r['trial'] == oracle):.4f} | {outer_of[oracle]:.4f} |",
          flush=True)


def _inner_valid(plan):
    from nnfmu.training.horizons import validation_trajectories

    valid, _ = validation_trajectories(plan.data, plan.train_config)
    return valid


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("datasets", nargs="+", type=Path)
    p.add_argument("--minutes", type=float, default=20.0, help="each search's budget (default 20)")
    p.add_argument("--work", type=Path, required=True, help="a folder for the searches' trials")
    p.add_argument("--reseed-after", type=float, default=None, metavar="F",
                   help="the share of the budget after which the search trains further seeds of its best points "
                        "(nnfmu.study.time_search.RESEED_AFTER; default: the search's own; 1: only once every point "
                        "has started, as before)")
    p.add_argument("--halving", choices=("arch", "all"), default=None,
                   help="what successive halving compares a trial with: the trials of its architecture, or all "
                        "(nnfmu.study.time_search.HALVING_BY; default: the search's own)")
    p.add_argument("--rescore", action="store_true",
                   help="no new search: compare the rules on the trials an earlier run kept in --work")
    args = p.parse_args()
    if args.reseed_after is not None:
        time_search.RESEED_AFTER = args.reseed_after
    if args.halving is not None:
        time_search.HALVING_BY = args.halving
    for path in args.datasets:
        compare(path, args.minutes, args.work / path.name, args.rescore)


if __name__ == "__main__":
    main()
