"""Atomic file writes: a file is either the old one, the complete new one, or absent; never half-written.

Every writer in nnfmu (datasets aside, which replace a whole folder) goes through
:func:`write_atomic`: the content is written to a temporary file beside the target,
which is then renamed into place with :func:`os.replace`, atomic on POSIX and Windows.
"""

from __future__ import annotations

import os
import tempfile
from pathlib import Path
from typing import Callable


def write_atomic(path: str | os.PathLike, write: Callable[[Path], None], suffix: str = "") -> Path:
    """Call ``write(tmp)`` on a temporary file beside ``path``, then rename it into place.

    ``suffix`` ends the temporary name (e.g. ``".npz"`` or ``".png"``) for writers that
    choose the format by extension. The parent folder is created; on any error,
    including Ctrl-C, the temporary file is removed and the exception propagates.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=f".tmp{suffix}", dir=path.parent)
    os.close(fd)
    try:
        write(Path(tmp))
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    return path


def write_text_atomic(path: str | os.PathLike, text: str) -> Path:
    """Write ``text`` (UTF-8) to ``path`` atomically."""
    return write_atomic(path, lambda tmp: tmp.write_text(text, encoding="utf-8"))
