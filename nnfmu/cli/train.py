"""``nnfmu train --data DIR --arch ARCH --strategy STRATEGY --out model.pt [options]``.

Trains one network with the one trainer, shows a progress bar with the loss
and the validation free-run NRMSE, writes the checkpoint after every epoch,
and prints the free-run test NRMSE of the best weights. Ctrl-C (or SIGTERM)
stops and keeps the best checkpoint; ``--resume`` continues it.
"""

from __future__ import annotations

import argparse

_DESCRIPTION = (
    "Train a network on a dataset folder, parallel (free-run loss) or series-parallel (one-step-ahead "
    "loss). A progress bar shows the loss and the validation free-run NRMSE; the checkpoint is written "
    "after every epoch and the free-run test NRMSE of the best weights is printed at the end. Ctrl-C "
    "stops and keeps the best checkpoint; --resume continues it."
)

# (option, ModelConfig/TrainConfig field, type, help). The defaults live in the config classes; the
# "(default ...)" texts are checked against them by tests/test_train_cli.py.
_MODEL_OPTIONS = (
    ("--hidden", "hidden", int, "width of the hidden layers / recurrent state (default 32)"),
    ("--layers", "layers", int, "hidden layers (MLP), stacked recurrent layers, or TCN layers (default per arch)"),
    ("--window", "window", int, "past samples seen by the MLP (default 4); the TCN's must equal its receptive field"),
    ("--dropout", "dropout", float, "dropout probability on hidden activations (default 0)"),
)
_TRAIN_OPTIONS = (
    ("--lr", "lr", float, "AdamW learning rate (default 3e-3)"),
    ("--weight-decay", "weight_decay", float, "AdamW weight decay (default 1e-4)"),
    ("--clip", "clip", float, "gradient-norm clipping, 0 = off (default 1)"),
    ("--epochs", "epochs", int, "maximum epochs (default 100)"),
    ("--patience", "patience", int, "early-stopping patience in epochs, 0 = off (default 15)"),
    ("--batch-size", "batch_size", int, "trajectories or windows per step (default 64)"),
    ("--truncate", "truncate", int, "train on windows of this many samples (multiple shooting; default: whole)"),
    ("--seed", "seed", int, "random seed (default 0)"),
    ("--max-minutes", "max_minutes", float, "wall-clock budget in minutes (default: none)"),
)


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("train", help="train a network (parallel or series-parallel) on a dataset folder",
                       description=_DESCRIPTION)
    p.add_argument("--data", required=True, help="dataset folder (meta.json, train.npz, test.npz[, valid.npz])")
    p.add_argument("--arch", choices=["mlp", "rnn", "lstm", "gru", "tcn"], help="network architecture")
    p.add_argument("--strategy", choices=["parallel", "series-parallel"],
                   help="parallel (free-run loss, default) or series-parallel (one-step-ahead loss)")
    p.add_argument("--out", required=True, help="checkpoint file to write (.pt)")
    for flag, dest, typ, text in _MODEL_OPTIONS + _TRAIN_OPTIONS:
        p.add_argument(flag, dest=dest, type=typ, default=None, help=text)
    p.add_argument("--resume", action="store_true", help="continue the training stored in --out")
    p.add_argument("--force", action="store_true", help="overwrite an existing --out file")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=_run)


def _given(args: argparse.Namespace, options) -> dict:
    return {dest: getattr(args, dest) for _, dest, _, _ in options if getattr(args, dest) is not None}


def _train_config(args: argparse.Namespace, stored: dict | None):
    from nnfmu.training import TrainConfig

    changes = _given(args, _TRAIN_OPTIONS)
    if args.strategy is not None:
        changes["strategy"] = args.strategy
    base = TrainConfig.from_dict(stored) if stored else TrainConfig()
    return base.replace(**changes)


def _model_config(args: argparse.Namespace, ds, stored: dict | None):
    from nnfmu.errors import ConfigError
    from nnfmu.models import ModelConfig

    given = _given(args, _MODEL_OPTIONS)
    if stored is not None:
        config = ModelConfig.from_dict(stored)
        clash = {k: v for k, v in given.items() if getattr(config, k) != v}
        if args.arch is not None and args.arch != config.arch:
            clash["arch"] = args.arch
        if clash:
            raise ConfigError(f"--resume continues the stored model {config}; the options {clash} differ. "
                              "Drop them, or train into a new --out file")
        return config
    if args.arch is None:
        raise ConfigError("--arch is required (mlp, rnn, lstm, gru or tcn) unless --resume is given")
    return ModelConfig(arch=args.arch, n_u=ds.n_u, n_y=ds.n_y, **given)


def _run(args: argparse.Namespace) -> int:
    from pathlib import Path

    from nnfmu.data import load_dataset
    from nnfmu.errors import ConfigError
    from nnfmu.models import load_checkpoint
    from nnfmu.training import train

    out = Path(args.out)
    ds = load_dataset(args.data)
    stored = load_checkpoint(out) if args.resume else None
    if stored is None and out.exists() and not args.force:
        raise ConfigError(f"{out} exists; pass --resume to continue it, --force to overwrite it, or another --out")
    model_config = _model_config(args, ds, None if stored is None else stored["model_config"])
    train_config = _train_config(args, None if stored is None else stored.get("train_config"))
    result = train(ds, model_config, train_config, out=out, resume=args.resume, progress=not args.quiet)
    for note in result.notes:
        print(f"note: {note}")
    print(f"stopped: {result.stop_reason}; best epoch {result.best_epoch}, "
          f"validation free-run NRMSE {result.best_valid_nrmse:.4f}; checkpoint {out}")
    if result.stop_reason in ("SIGINT", "SIGTERM"):
        print(f"interrupted: the best checkpoint so far is kept; continue with --resume --out {out}")
        return 130
    if result.test is None:
        print("test free-run NRMSE: n/a (no test split, or the free run diverged)")
        return 0
    per_output = ", ".join(f"{c.name} {v:.4f}" for c, v in zip(ds.outputs, result.test.output_mean))
    print(f"test free-run NRMSE: {result.test.mean:.4f} ({per_output})")
    return 0
