"""``nnfmu evaluate --data DIR A.fmu B.fmu ...``: co-simulate FMUs in fmpy and score them with NRMSE."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from nnfmu.atomic import write_text_atomic


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("evaluate", help="co-simulate FMUs on a dataset split in fmpy and print their NRMSE")
    p.add_argument("fmus", nargs="+", help="FMU files to score")
    p.add_argument("--data", required=True, help="dataset folder")
    p.add_argument("--split", default="test", choices=["train", "valid", "test"], help="split to score (default test)")
    p.add_argument("--json", help="write the scores to this JSON file")
    p.add_argument("--plots", help="write a PNG of predicted vs measured outputs into this folder")
    p.add_argument("--trajectory", type=int, help="trajectory to plot (default: the median-scored one)")
    p.set_defaults(func=_run)


def format_table(evaluations, output_names) -> str:
    """A plain-text table: one row per model, the mean NRMSE and the per-output values."""
    width = max([len("model")] + [len(ev.name) for ev in evaluations])
    head = f"{'model':<{width}}  {'NRMSE':>8}  " + "  ".join(f"{n:>8}" for n in output_names)
    lines = [head, "-" * len(head)]
    for ev in evaluations:
        per = "  ".join(f"{v:8.4f}" for v in ev.result.output_mean)
        lines.append(f"{ev.name:<{width}}  {ev.result.mean:8.4f}  {per}")
    return "\n".join(lines)


def _run(args: argparse.Namespace) -> int:
    from nnfmu.cosim import evaluate
    from nnfmu.data import load_dataset

    ds = load_dataset(args.data)
    evaluations = evaluate(args.fmus, ds, split=args.split, progress=True)
    print(f"NRMSE on {args.data} ({args.split}: {ds.split(args.split).n_traj} trajectories, free run from measured y0)")
    print(format_table(evaluations, ds.output_names))
    for ev in evaluations:  # the FMU warns on these samples: its outputs there are extrapolated
        if ev.out_of_range is not None:
            print(f"inputs outside the valid range of {ev.name}: {ev.out_of_range.describe()}")
    if args.json:
        doc = {"data": str(args.data), "split": args.split, "Ts": ds.Ts,
               "models": [ev.to_json(ds.output_names) for ev in evaluations]}
        write_text_atomic(args.json, json.dumps(doc, indent=2) + "\n")
        print(f"scores written to {args.json}")
    if args.plots:
        from nnfmu.plots import plot_trajectory

        png = plot_trajectory(ds, evaluations, Path(args.plots) / f"{args.split}_trajectory.png",
                              split=args.split, index=args.trajectory)
        print(f"plot written to {png}")
    return 0
