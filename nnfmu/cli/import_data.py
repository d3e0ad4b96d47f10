"""``nnfmu import robot-benchmark FILE --out DIR``: external data to a dataset folder."""

from __future__ import annotations

import argparse


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("import", help="convert external data into a dataset folder")
    p.add_argument("format", choices=["robot-benchmark"], help="the external format")
    p.add_argument("file", help="the file to read (for robot-benchmark: the benchmark's .mat)")
    p.add_argument("--out", required=True, help="dataset folder to write")
    p.add_argument("--force", action="store_true", help="replace an existing dataset folder")
    p.set_defaults(func=_run)


def _run(args: argparse.Namespace) -> int:
    from nnfmu.data import load_robot_benchmark, save_dataset

    ds = load_robot_benchmark(args.file)
    save_dataset(ds, args.out, overwrite=args.force)
    print(f"wrote {args.out}")
    print(ds.summary())
    if "caveat" in ds.source:
        print(f"caveat: {ds.source['caveat']}")
    return 0
