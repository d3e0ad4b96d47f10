"""What a failed command leaves behind: nothing, for a command that writes several files; for a failed or
stopped ``nnfmu train``, nothing unless an epoch finished.

A command with several targets (``linear -o X.fmu --save X.json``, ``evaluate -o DIR``) first checks that
every target's folder takes a new file (:func:`check_writable`), then writes them inside
:func:`all_or_nothing`, which removes what it wrote if a later write fails (a full disk).

The trainer writes the checkpoint before the first epoch (the untrained
network, epoch 0) so that ``--resume`` always has a file. If the command then
fails or is stopped before any training epoch finishes, that file holds
nothing worth keeping, and ``export`` would happily turn it into an FMU; a
checkpoint this command created is therefore removed again. Once an epoch has
finished, the checkpoint is kept: it is the resumable work.
"""

from __future__ import annotations

import contextlib
import os
import shutil
import tempfile
from pathlib import Path


def _existing_ancestor(path: Path) -> Path:
    while not path.exists() and path != path.parent:
        path = path.parent
    return path


def _outermost_missing(path: Path) -> Path | None:
    """The outermost of ``path`` and its ancestors that does not exist (None if ``path`` exists)."""
    top = None
    while not path.exists() and path != path.parent:
        top, path = path, path.parent
    return top


def check_writable(*targets: str | os.PathLike | None) -> None:
    """Raise :class:`~nnfmu.errors.DataFileError` naming the first target whose folder refuses a new file.

    The probe creates and removes a file in the nearest existing folder (``os.access`` says yes to root even
    on a read-only mount); a regular file in the way is named as such, and so is a device node, FIFO or socket
    at the target. A symbolic link is checked where it points: the write goes there.
    """
    from nnfmu.atomic import describe_os_error, resolve_target
    from nnfmu.errors import DataFileError

    for target in targets:
        if target is None:
            continue
        target = resolve_target(target)
        folder = _existing_ancestor(target.parent)
        if not folder.is_dir():
            raise DataFileError(f"cannot write {target}: {folder} is a file, not a folder; choose another path")
        try:
            fd, probe = tempfile.mkstemp(prefix=".nnfmu-probe-", dir=folder)
            os.close(fd)
            os.unlink(probe)
        except OSError as exc:
            raise DataFileError(f"cannot write {describe_os_error(exc, target, doing='write')}") from exc


@contextlib.contextmanager
def all_or_nothing(*targets: str | os.PathLike | None):
    """If the block fails, remove what it created of ``targets`` (files or folders) and their missing parents."""
    fresh = [top for t in targets if t is not None and (top := _outermost_missing(Path(t))) is not None]
    try:
        yield
    except BaseException:
        for path in fresh:
            if path.is_dir():
                shutil.rmtree(path, ignore_errors=True)
            elif path.exists():
                path.unlink(missing_ok=True)
        raise


def remove_if_untrained(out: Path) -> bool:
    """Delete the checkpoint at ``out`` if no training epoch finished in it; True if it was removed."""
    from nnfmu.errors import CheckpointError
    from nnfmu.models import load_checkpoint

    if not out.is_file():
        return False
    try:
        ckpt = load_checkpoint(out)
    except CheckpointError:
        return False  # not ours to judge: leave it
    if int((ckpt.get("resume") or {}).get("epoch", 0)) > 0:
        return False
    out.unlink(missing_ok=True)
    return True
