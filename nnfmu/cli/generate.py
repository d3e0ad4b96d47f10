"""``nnfmu generate SPEC --out DIR [--size SIZE] [--seed N] [--noise F] [--force]``: simulate a dataset folder.

SPEC is a built-in model (valve, arm, slider: their own generators, physics.md) or a model of your own,
``path/to/file.py:NAME`` or a ``.json`` physics document (:mod:`nnfmu.physics.generate_model`: the
toolkit's excitation signals within its input ranges). Loading a ``.py`` file runs its code.
"""

from __future__ import annotations

import argparse
import os
import shutil
import sys
import tempfile
from pathlib import Path

from nnfmu.errors import ConfigError

SYSTEMS = ("arm", "slider", "valve")  # sizes: nnfmu.physics.DATASET_SIZES (imported late: it pulls in CasADi)
USER_SIZES = ("standard", "small")  # nnfmu.physics.generate_model.MODEL_SIZES


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("generate", help="simulate a physics model (built-in or your own) into a dataset folder",
                       description="Simulate a physics model and write its dataset folder (meta.json, train.npz, "
                                   "test.npz): a built-in one (physics.md) or your own (docs/own-physics.md).")
    p.add_argument("system", metavar="SPEC",
                   help=f"the physics model: {', '.join(SYSTEMS)}, or path/to/file.py:NAME (runs that file's code) "
                        f"or a .json physics document")
    p.add_argument("-o", "--out", required=True, help="dataset folder to write")
    p.add_argument("--size", default=None,
                   help="valve: paper (default; 900 x 500 train, 30 x 3500 test) or small; "
                        "arm: benchmark (default; ~40 000 train samples, one 3600-sample test record) or small; "
                        "slider and a model of your own: standard (default; 40 x 1000 train, 4 x 4000 valid and "
                        "test) or small (16 x 400, 2 x 1600)")
    p.add_argument("--seed", type=int, default=0, help="non-negative random seed (default 0)")
    p.add_argument("--noise", type=float, default=0.0, metavar="F",
                   help="add white Gaussian measurement noise to the outputs, its std F times each output's std "
                        "over the training split (default 0: none)")
    p.add_argument("--force", action="store_true", help="replace an existing dataset folder")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.epilog = ("Stopping a slow generation (the arm) keeps the finished trajectories in .<out>.partial "
                "beside the target; the same command resumes from them.")
    p.set_defaults(func=_run)


def _check_writable(out: Path, force: bool) -> None:
    """Fail before simulating (which can take minutes) if the result could not be written."""
    from nnfmu.errors import DataFileError

    from nnfmu.data.storage import check_replaceable

    if out.exists() and not force:
        raise DataFileError(f"{out} already exists; choose another folder or pass --force")
    check_replaceable(out)  # --force replaces a dataset folder, never a folder of other files
    ancestor = out.resolve().parent
    while not ancestor.exists():
        ancestor = ancestor.parent
    try:  # a real probe: permission bits say nothing for root or read-only mounts
        os.rmdir(tempfile.mkdtemp(prefix=".nnfmu_probe_", dir=ancestor))
    except OSError as exc:
        raise DataFileError(f"cannot write the dataset folder {out}: {ancestor} is not a writable folder "
                            f"({exc.strerror or exc}); choose a writable location with --out") from exc


def _generate(args: argparse.Namespace, out: Path):
    """The dataset: a built-in model's own generator, or the generic one for a model of the user's own."""
    from nnfmu.physics import DATASET_SIZES, check_request, generate_dataset, resolve_physics
    from nnfmu.physics.generate_model import add_noise, generate_model_dataset

    if args.system in SYSTEMS:
        size = args.size or DATASET_SIZES[args.system][0]
        check_request(args.system, size, args.seed)
        _check_writable(out, args.force)
        partial = out.resolve().parent / f".{out.name}.partial"
        ds = generate_dataset(args.system, size=size, seed=args.seed,
                              progress=not args.quiet and sys.stderr.isatty(), partial_dir=partial)
        return add_noise(ds, args.noise, args.seed), partial
    system = resolve_physics(args.system)  # a model file, a document, or a model registered by a plug-in
    size = args.size or USER_SIZES[0]
    if size not in USER_SIZES:
        raise ConfigError(f"unknown size {size!r} for {system.name}; valid sizes are {', '.join(USER_SIZES)}")
    _check_writable(out, args.force)
    return generate_model_dataset(system, size=size, seed=args.seed, noise=args.noise), None


def _run(args: argparse.Namespace) -> int:
    from nnfmu.data import save_dataset

    out = Path(args.out)
    ds, partial = _generate(args, out)
    save_dataset(ds, out, overwrite=args.force)
    if partial is not None:
        shutil.rmtree(partial, ignore_errors=True)
    print(f"wrote {out}")
    print(ds.summary())
    return 0
