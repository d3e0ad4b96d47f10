"""``nnfmu generate SPEC --out DIR [--size SIZE] [--seed N] [--noise F] [--force]``: simulate a dataset folder.

SPEC is a registered model (:func:`nnfmu.physics.physics_names`: the built-in ones have their own generators,
physics.md) or a model of your own, ``path/to/file.py:NAME`` or a ``.json`` physics document
(:mod:`nnfmu.physics.generate_model`: the toolkit's excitation signals within its input ranges). Loading a
``.py`` file runs its code. A registered model's generator and sizes come from its registry entry.
"""

from __future__ import annotations

import argparse
import os
import shutil
import sys
import tempfile
from pathlib import Path

from nnfmu.cli._arch import LazyChoices
from nnfmu.cli._physics_info import physics_names
from nnfmu.errors import ConfigError

USER_SIZES = ("standard", "small")  # nnfmu.physics.generate_model.MODEL_SIZES


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("generate", help="simulate a physics model (built-in or your own) into a dataset folder",
                       description="Simulate a physics model and write its dataset folder (meta.json, train.npz, "
                                   "test.npz): a built-in one (physics.md) or your own (docs/own-physics.md).")
    p.add_argument("system", metavar="SPEC", choices=LazyChoices(physics_names, open_choices=True),
                   help="the physics model: a registered one (%(choices)s; physics.md), or path/to/file.py:NAME "
                        "(runs that file's code) or a .json physics document")
    p.add_argument("-o", "--out", required=True, help="dataset folder to write")
    p.add_argument("--size", default=None, metavar="SIZE", choices=LazyChoices(_sizes, open_choices=True),
                   help="the dataset's size, the first of a model's sizes its default (full) one: %(choices)s; "
                        "a model file or document: standard (default; 40 x 1000 train, 4 x 4000 valid and test) "
                        "or small (16 x 400, 2 x 1600); physics.md gives the built-in sizes")
    p.add_argument("--seed", type=int, default=0, help="non-negative random seed (default 0)")
    p.add_argument("--noise", type=float, default=0.0, metavar="F",
                   help="add white Gaussian measurement noise to the outputs, its std F times each output's std "
                        "over the training split (default 0: none)")
    p.add_argument("--force", action="store_true", help="replace an existing dataset folder")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.epilog = ("Stopping a slow generation (the arm) keeps the finished trajectories in .<out>.partial "
                "beside the target; the same command resumes from them.")
    p.set_defaults(func=_run)


def _sizes() -> list[str]:
    """``NAME: SIZE|SIZE`` per registered model, for the help."""
    from nnfmu.physics import physics_entry, physics_names

    return [f"{name} {'|'.join(physics_entry(name).sizes)}" for name in physics_names()]


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
    """The dataset: a registered model's generator, or the generic one for a model file or document."""
    from nnfmu.physics import check_request, generate_dataset, physics_entry, physics_names, resolve_physics
    from nnfmu.physics.generate_model import add_noise, generate_model_dataset

    if args.system in physics_names() and physics_entry(args.system).generate is not None:
        size = args.size or physics_entry(args.system).sizes[0]
        check_request(args.system, size, args.seed)
        _check_writable(out, args.force)
        partial = out.resolve().parent / f".{out.name}.partial"
        ds = generate_dataset(args.system, size=size, seed=args.seed,
                              progress=not args.quiet and sys.stderr.isatty(), partial_dir=partial)
        return add_noise(ds, args.noise, args.seed), partial
    system = resolve_physics(args.system)  # a model file, a document, or a registered model without a generator
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
