"""``nnfmu generate valve|arm|slider --out DIR [--size SIZE] [--seed N] [--force]``: simulate a dataset folder."""

from __future__ import annotations

import argparse
import os
import shutil
import sys
import tempfile
from pathlib import Path

SYSTEMS = ("arm", "slider", "valve")  # sizes: nnfmu.physics.DATASET_SIZES (imported late: it pulls in CasADi)


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("generate", help="simulate a physics reference model into a dataset folder",
                       description="Simulate a physics reference model (physics.md) and write its dataset "
                                   "folder (meta.json, train.npz, test.npz).")
    p.add_argument("system", choices=SYSTEMS, help="the physics model to simulate")
    p.add_argument("-o", "--out", required=True, help="dataset folder to write")
    p.add_argument("--size", default=None,
                   help="valve: paper (default; 900 x 500 train, 30 x 3500 test) or small; "
                        "arm: benchmark (default; ~40 000 train samples, one 3600-sample test record) or small; "
                        "slider: standard (default; 40 x 1000 train, 4 x 4000 valid and test) or small")
    p.add_argument("--seed", type=int, default=0, help="non-negative random seed (default 0)")
    p.add_argument("--force", action="store_true", help="replace an existing dataset folder")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.epilog = ("Stopping a slow generation (the arm) keeps the finished trajectories in .<out>.partial "
                "beside the target; the same command resumes from them.")
    p.set_defaults(func=_run)


def _check_writable(out: Path, force: bool) -> None:
    """Fail before simulating (which can take minutes) if the result could not be written."""
    from nnfmu.errors import DataFileError

    if out.exists() and not force:
        raise DataFileError(f"{out} already exists; choose another folder or pass --force")
    if out.exists() and not out.is_dir():
        raise DataFileError(f"{out} is a file, expected a dataset folder; choose another path")
    ancestor = out.resolve().parent
    while not ancestor.exists():
        ancestor = ancestor.parent
    try:  # a real probe: permission bits say nothing for root or read-only mounts
        os.rmdir(tempfile.mkdtemp(prefix=".nnfmu_probe_", dir=ancestor))
    except OSError as exc:
        raise DataFileError(f"cannot write the dataset folder {out}: {ancestor} is not a writable folder "
                            f"({exc.strerror or exc}); choose a writable location with --out") from exc


def _run(args: argparse.Namespace) -> int:
    from nnfmu.data import save_dataset
    from nnfmu.physics import DATASET_SIZES, check_request, generate_dataset

    size = args.size or DATASET_SIZES[args.system][0]
    check_request(args.system, size, args.seed)
    out = Path(args.out)
    _check_writable(out, args.force)
    partial = out.resolve().parent / f".{out.name}.partial"
    ds = generate_dataset(args.system, size=size, seed=args.seed, progress=not args.quiet and sys.stderr.isatty(),
                          partial_dir=partial)
    save_dataset(ds, out, overwrite=args.force)
    shutil.rmtree(partial, ignore_errors=True)
    print(f"wrote {out}")
    print(ds.summary())
    return 0
