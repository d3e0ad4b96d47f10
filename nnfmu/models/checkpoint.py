"""Checkpoints: one ``torch.save`` file of plain dicts, lists, tensors, numbers and strings.

A checkpoint loads with ``torch.load(path, weights_only=True)`` (never
unrestricted pickle) and holds::

    format, version          "nnfmu-checkpoint", 1
    model_config             ModelConfig.to_dict()
    meta                     Ts, inputs, outputs ({name, unit}) and source of the dataset
    state_dict               the BEST weights (validation free-run NRMSE), normalisation buffers included
    train_config             TrainConfig.to_dict() (or None)
    history                  one dict of metrics per epoch
    best_epoch               epoch of state_dict (0 = before training)
    summary                  figures for humans and provenance (best validation NRMSE, test NRMSE ...)
    resume                   what ``--resume`` needs: the LATEST weights, optimizer state, epoch,
                             torch RNG state, early-stopping counter, elapsed time (or None)

Files are written atomically (:func:`nnfmu.atomic.write_atomic`), so an
interrupted write never leaves a half checkpoint behind; a write error names
the file and its cause (:class:`~nnfmu.errors.DataFileError`). A file that
would need unrestricted unpickling is refused with a message that says why
(it could run code), never with torch's advice to load it anyway.
"""

from __future__ import annotations

import io
import os
import pickle
import re
from pathlib import Path
from typing import Mapping

import torch

from nnfmu.atomic import describe_os_error, write_atomic
from nnfmu.errors import CheckpointError, NnfmuError
from nnfmu.models.base import StepModel
from nnfmu.models.config import ModelConfig
from nnfmu.models.registry import build_model

FORMAT = "nnfmu-checkpoint"
VERSION = 1
_REQUIRED = ("model_config", "meta", "state_dict")
_UNSUPPORTED = re.compile(r"(?i)unsupported (GLOBAL [\w.]+)")


def state_snapshot(model: torch.nn.Module) -> dict:
    """Detached CPU copies of the model's weights and buffers (a ``state_dict`` that later training cannot
    change, and that loads on any device)."""
    return {k: v.detach().to("cpu", copy=True) for k, v in model.state_dict().items()}


def save_checkpoint(
    path: str | os.PathLike,
    model: StepModel,
    *,
    state_dict: Mapping | None = None,
    train_config: Mapping | None = None,
    history: list | None = None,
    best_epoch: int | None = None,
    summary: Mapping | None = None,
    resume: Mapping | None = None,
) -> Path:
    """Write a checkpoint of ``model`` atomically; returns the path.

    Parameters
    ----------
    path : path of the ``.pt`` file; parent folders are created.
    model : the network (its config, meta and, unless ``state_dict`` is given, its weights).
    state_dict : weights to store instead of the model's current ones (the best epoch's).
    train_config, history, best_epoch, summary, resume : see the module docstring.
    """
    path = Path(path)
    payload = {
        "format": FORMAT,
        "version": VERSION,
        "model_config": model.config.to_dict(),
        "meta": dict(model.meta),
        "state_dict": dict(state_dict) if state_dict is not None else state_snapshot(model),
        "train_config": None if train_config is None else dict(train_config),
        "history": list(history or []),
        "best_epoch": best_epoch,
        "summary": dict(summary or {}),
        "resume": None if resume is None else dict(resume),
    }
    buffer = io.BytesIO()  # serialise in memory: torch's own file writer turns a full disk into a RuntimeError
    torch.save(payload, buffer)
    return write_atomic(path, lambda tmp: tmp.write_bytes(buffer.getbuffer()))



def load_checkpoint(path: str | os.PathLike) -> dict:
    """Read and check a checkpoint file; returns its dict (see the module docstring).

    Raises
    ------
    CheckpointError
        If the file is missing, unreadable or corrupt, or not an nnfmu checkpoint.
    """
    path = Path(path)
    if not path.is_file():
        raise CheckpointError(f"no checkpoint file at {path}; pass the .pt file written by 'nnfmu train --out'")
    try:
        ckpt = torch.load(path, map_location="cpu", weights_only=True)
    except OSError as exc:  # the file cannot be opened (permissions ...), or its zip structure is broken
        if exc.filename is None:
            raise _unreadable(path, exc) from None
        raise CheckpointError(f"cannot read the checkpoint {describe_os_error(exc, path)}") from exc
    except Exception as exc:  # torch raises many types for corrupt or foreign files
        raise _unreadable(path, exc) from None
    if not isinstance(ckpt, dict) or ckpt.get("format") != FORMAT:
        raise CheckpointError(f"{path} is a torch file but not an nnfmu checkpoint (expected format {FORMAT!r}); "
                              "train a model with 'nnfmu train' to get one")
    if not isinstance(ckpt.get("version"), int) or ckpt["version"] > VERSION:
        raise CheckpointError(f"{path} has checkpoint version {ckpt.get('version')!r}, this nnfmu reads up to "
                              f"{VERSION}; upgrade nnfmu")
    missing = [k for k in _REQUIRED if k not in ckpt]
    if missing:
        raise CheckpointError(f"{path} lacks {missing}; the checkpoint is damaged, train again")
    return ckpt


def _unreadable(path: Path, exc: Exception) -> CheckpointError:
    """The error for a file torch cannot load with weights_only=True; never repeats torch's advice to
    load it with weights_only=False (that would run whatever code the file holds)."""
    text = str(exc)
    if isinstance(exc, pickle.UnpicklingError) and "weights only load failed" in text.lower() and \
            _holds_globals(path):
        found = _UNSUPPORTED.search(text)
        return CheckpointError(
            f"{path} is not a plain nnfmu checkpoint: it holds Python objects"
            f"{f' ({found.group(1)})' if found else ''} that only unrestricted unpickling could load, which can "
            f"run code hidden in the file; nnfmu refuses it. Do not load it with weights_only=False; use a "
            f"checkpoint written by 'nnfmu train'")
    if "weights only load failed" in text.lower():  # torch's text would advise weights_only=False: never repeat it
        return CheckpointError(f"{path} is not an nnfmu checkpoint (corrupt, truncated or another file type); use a "
                               "checkpoint written by 'nnfmu train'")
    return CheckpointError(f"{path} is not a readable torch checkpoint (corrupt, truncated or another file "
                           f"type): {type(exc).__name__}: {text.splitlines()[0] if text else ''}")


def _holds_globals(path: Path) -> bool:
    """Whether ``path`` is a pickle (plain, or torch's zip with its ``data.pkl``) that names Python objects to build:
    only such a file earns the warning about code; random bytes or text are just not a checkpoint."""
    import pickletools
    import zipfile

    try:
        if zipfile.is_zipfile(path):
            with zipfile.ZipFile(path) as archive:
                names = [n for n in archive.namelist() if n.endswith("data.pkl")]
                data = archive.read(names[0]) if names else b""
        else:
            data = path.read_bytes()
        return any(op.name in ("GLOBAL", "STACK_GLOBAL", "INST", "OBJ", "REDUCE")
                   for op, _, _ in pickletools.genops(data))
    except Exception:  # not a pickle at all (an unknown opcode, truncated): no objects in it
        return False


def model_from_checkpoint(ckpt: Mapping, state_dict: Mapping | None = None, where: str = "checkpoint") -> StepModel:
    """Rebuild the network of a loaded checkpoint dict with its best weights (or ``state_dict``)."""
    try:
        model = build_model(ModelConfig.from_dict(ckpt["model_config"]), ckpt["meta"])
        model.load_state_dict(dict(ckpt["state_dict"] if state_dict is None else state_dict))
    except (NnfmuError, RuntimeError, TypeError, KeyError) as exc:
        raise CheckpointError(f"{where}: the stored weights do not fit the stored model config ({exc}); "
                              "the checkpoint is damaged or from an incompatible nnfmu version") from exc
    return model


def load_model(path: str | os.PathLike) -> StepModel:
    """Load a trained network from a checkpoint written by ``nnfmu train``.

    Returns the model in eval mode with its best weights; ``model.provenance``
    records the checkpoint path, best epoch, training config and summary.

    Raises
    ------
    CheckpointError
        If the file is missing, corrupt or not an nnfmu checkpoint.
    """
    ckpt = load_checkpoint(path)
    model = model_from_checkpoint(ckpt, where=str(path))
    model.provenance = {
        "checkpoint": str(Path(path).resolve()),
        "best_epoch": ckpt.get("best_epoch"),
        "train_config": ckpt.get("train_config"),
        "summary": ckpt.get("summary", {}),
        "dataset_source": ckpt["meta"].get("source", {}),
    }
    return model.eval()
