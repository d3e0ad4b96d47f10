"""Temporary folders in the system temp directory that a killed process does not leave there for good.

A folder from :func:`private_temp_dir` is named ``<prefix><pid>-<random>``; every new one first removes the
folders of the same prefix whose process is gone (a SIGKILL, a power loss: no ``finally`` ran), using the
same liveness test as :mod:`nnfmu.atomic`'s temporary files. Folders of running processes, and names
without a pid (earlier versions), are left alone.
"""

from __future__ import annotations

import contextlib
import os
import re
import shutil
import tempfile
from pathlib import Path
from typing import Iterator

from nnfmu.atomic import _pid_alive


def remove_stale_temp_dirs(prefix: str, parent: str | os.PathLike | None = None) -> list[Path]:
    """Remove ``<prefix><pid>-*`` folders in ``parent`` (default: the system temp dir) whose pid is gone."""
    parent = Path(parent or tempfile.gettempdir())
    pattern = re.compile(rf"{re.escape(prefix)}(\d+)-[0-9a-z_]+")
    removed = []
    try:
        entries = list(parent.iterdir())
    except OSError:
        return removed
    for entry in entries:
        match = pattern.fullmatch(entry.name)
        if match and int(match.group(1)) != os.getpid() and not _pid_alive(int(match.group(1))):
            with contextlib.suppress(OSError):
                if entry.is_dir() and not entry.is_symlink():
                    shutil.rmtree(entry)
                    removed.append(entry)
    return removed


def make_temp_dir(prefix: str) -> Path:
    """A new ``<prefix><pid>-<random>`` folder in the system temp dir, after removing stale ones; the caller
    removes it (see :func:`private_temp_dir`)."""
    remove_stale_temp_dirs(prefix)
    return Path(tempfile.mkdtemp(prefix=f"{prefix}{os.getpid()}-"))


@contextlib.contextmanager
def private_temp_dir(prefix: str) -> Iterator[str]:
    """Like ``tempfile.TemporaryDirectory(prefix=...)``, with the owner's pid in the name (module docstring)."""
    path = make_temp_dir(prefix)
    try:
        yield str(path)
    finally:
        shutil.rmtree(path, ignore_errors=True)
