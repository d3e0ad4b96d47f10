"""``nnfmu evaluate --data DIR A.fmu B.fmu ...``: co-simulate FMUs in fmpy and score them with NRMSE."""

from __future__ import annotations

import argparse
import dataclasses
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
    p.add_argument("--init-window", dest="init_window", type=int, metavar="N",
                   help="the models may see the first N measured samples (FMUs with window parameters get them) "
                        "and are scored on the rest, as the identification benchmarks do (default: the "
                        "dataset's init_window from meta.json, else 1: the free run from y0, every sample scored)")
    p.add_argument("--horizon", type=int, metavar="H",
                   help="H-step-ahead prediction: restart every model from the measured output every H samples "
                        "(default: one free run per trajectory, the headline protocol)")
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


def _protocol(args: argparse.Namespace, ds):
    """The evaluation protocol (nnfmu.protocols) from --init-window, --horizon and the dataset's init_window."""
    from nnfmu.protocols import Protocol

    window = args.init_window if args.init_window is not None else getattr(ds, "init_window", None)
    return Protocol(init_window=max(int(window or 1), 1), horizon=args.horizon)


def _run(args: argparse.Namespace) -> int:
    from nnfmu.cosim import evaluate
    from nnfmu.data import load_dataset

    ds = load_dataset(args.data)
    protocol = _protocol(args, ds)
    evaluations = evaluate(args.fmus, ds, split=args.split, progress=True, protocol=protocol)
    print(f"NRMSE on {args.data} ({args.split}: {ds.split(args.split).n_traj} trajectories, {protocol.describe()})")
    print(format_table(evaluations, ds.output_names))
    if args.json:
        doc = {"data": str(args.data), "split": args.split, "Ts": ds.Ts, "protocol": protocol.to_json(),
               "models": [ev.to_json(ds.output_names) for ev in evaluations]}
        write_text_atomic(args.json, json.dumps(doc, indent=2) + "\n")
        print(f"scores written to {args.json}")
    if args.plots:
        from nnfmu.plots import plot_trajectory

        measured = ds.split(args.split).y
        shown = [dataclasses.replace(ev, predictions=[protocol.padded(p, len(y)) for p, y in zip(ev.predictions,
                                                                                                    measured)])
                 for ev in evaluations]
        png = plot_trajectory(ds, shown, Path(args.plots) / f"{args.split}_trajectory.png",
                              split=args.split, index=args.trajectory)
        print(f"plot written to {png}")
    return 0
