"""``nnfmu evaluate --data DIR A.fmu B.fmu ...``: co-simulate FMUs in fmpy and score them.

Prints, per model, the NRMSE with the fit % and R² next to it and the per-output
NRMSE, then the RMSE and MAE of each output in its own unit; ``--json`` (or ``-o``)
writes them all per model, output and trajectory.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
from pathlib import Path

from nnfmu.atomic import write_text_atomic

_DESCRIPTION = (
    "Co-simulate FMUs in fmpy on a dataset split, each trajectory from its measured initial outputs, and score "
    "them: NRMSE (RMSE over the standard deviation of the measurement, per output, then the mean over outputs and "
    "trajectories), fit % = 100 (1 - NRMSE), R2 = 1 - NRMSE^2 (the coefficient of determination, averaged like "
    "the NRMSE), and the RMSE and MAE of each output in its own unit."
)


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("evaluate", help="co-simulate FMUs on a dataset split in fmpy and print NRMSE, fit %%, R2, "
                                        "RMSE and MAE",
                       description=_DESCRIPTION)
    p.add_argument("fmus", nargs="+", help="FMU files to score")
    p.add_argument("--data", required=True, help="dataset folder")
    p.add_argument("--split", default="test", choices=["train", "valid", "test"], help="split to score (default test)")
    p.add_argument("-o", "--out", metavar="DIR", help="write scores.json and the plot into this folder")
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


def _table(header: list[str], rows: list[list[str]]) -> list[str]:
    widths = [max(len(r[j]) for r in [header] + rows) for j in range(len(header))]
    line = lambda r: "  ".join(c.ljust(w) if j == 0 else c.rjust(w) for j, (c, w) in enumerate(zip(r, widths)))
    head = line(header)
    return [head, "-" * len(head)] + [line(r) for r in rows]


def format_table(evaluations, outputs) -> str:
    """Plain-text tables: per model the NRMSE, fit %, R² and per-output NRMSE; then each output's RMSE and MAE.

    ``outputs`` are the dataset's output Channels (names and units).
    """
    names = [getattr(o, "name", o) for o in outputs]
    scores = [["model", "NRMSE", "fit %", "R2"] + names]
    scores += [[ev.name, f"{ev.result.mean:.4f}", f"{ev.result.fit:.2f}", f"{ev.result.r2:.4f}"]
               + [f"{v:.4f}" for v in ev.result.output_mean] for ev in evaluations]
    units = [f"{n} [{getattr(o, 'unit', '') or '-'}]" for n, o in zip(names, outputs)]
    errors = [["model"] + [f"RMSE {u}" for u in units] + [f"MAE {u}" for u in units]]
    errors += [[ev.name] + [f"{v:.4g}" for v in ev.result.rmse_output_mean]
               + [f"{v:.4g}" for v in ev.result.mae_output_mean] for ev in evaluations]
    return "\n".join(["NRMSE, fit % and R2 (means over outputs), then the NRMSE of each output:"]
                     + _table(scores[0], scores[1:]) + ["", "RMSE and MAE of each output, in its unit:"]
                     + _table(errors[0], errors[1:]))


def _protocol(args: argparse.Namespace, ds):
    """The evaluation protocol (nnfmu.protocols) from --init-window, --horizon and the dataset's init_window."""
    from nnfmu.protocols import Protocol

    from nnfmu.cli._checks import check_window

    window = args.init_window if args.init_window is not None else getattr(ds, "init_window", None)
    check_window("--init-window", window, ds, [args.split])
    return Protocol(init_window=max(int(window or 1), 1), horizon=args.horizon)


def _run(args: argparse.Namespace) -> int:
    from nnfmu.cli._checks import check_index
    from nnfmu.cli._outputs import all_or_nothing, check_writable
    from nnfmu.cosim import evaluate
    from nnfmu.data import load_dataset

    ds = load_dataset(args.data)
    protocol = _protocol(args, ds)
    check_index("--trajectory", args.trajectory, ds.split(args.split).n_traj,
                f"trajectories in the {args.split} split")
    out = Path(args.out) if args.out else None
    json_path = args.json or (out / "scores.json" if out else None)
    plots = args.plots or (out if out else None)
    check_writable(json_path, plots and Path(plots) / "plot.png")  # before the (long) co-simulation
    # a bar on a terminal only: in a log or a pipe its redraws would be lines of noise
    evaluations = evaluate(args.fmus, ds, split=args.split, progress=sys.stderr.isatty(), protocol=protocol)
    print(f"{args.split} split of {args.data}: {ds.split(args.split).n_traj} trajectories, {protocol.describe()}; "
          "fit % = 100 (1 - NRMSE), R2 = 1 - NRMSE^2")
    print(format_table(evaluations, ds.outputs))
    for ev in evaluations:  # the FMU warns on these samples: its outputs there are extrapolated
        if ev.out_of_range is not None and ev.out_of_range.samples > 0:
            print(f"inputs outside the valid range of {ev.name}: {ev.out_of_range.describe()}")
    with all_or_nothing(out, json_path, plots):  # a failed write (a full disk) leaves none of them
        if plots:
            png = _plot(args, ds, protocol, evaluations, Path(plots))
        if json_path:
            write_text_atomic(json_path, json.dumps(_scores_json(args, ds, protocol, evaluations), indent=2) + "\n")
    if json_path:
        print(f"scores written to {json_path}")
    if plots:
        print(f"plot written to {png}")
    return 0


def _scores_json(args: argparse.Namespace, ds, protocol, evaluations) -> dict:
    return {"data": str(args.data), "split": args.split, "Ts": ds.Ts, "protocol": protocol.to_json(),
            "outputs": [c.to_json() for c in ds.outputs],
            "scoring": "per trajectory and output: RMSE and MAE in the output's unit, NRMSE = RMSE / std(measured), "
                       "fit_percent = 100 (1 - NRMSE), r2 = 1 - NRMSE^2; totals: mean over outputs (not RMSE or "
                       "MAE), then over trajectories",
            "models": [ev.to_json(ds.outputs) for ev in evaluations]}


def _plot(args: argparse.Namespace, ds, protocol, evaluations, folder: Path) -> Path:
    from nnfmu.plots import plot_trajectory

    measured = ds.split(args.split).y
    shown = [dataclasses.replace(ev, predictions=[protocol.padded(p, len(y)) for p, y in zip(ev.predictions,
                                                                                                measured)])
             for ev in evaluations]
    return plot_trajectory(ds, shown, folder / f"{args.split}_trajectory.png", split=args.split,
                           index=args.trajectory)
