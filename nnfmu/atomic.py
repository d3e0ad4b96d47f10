"""Atomic file writes: a file is either the old one, the complete new one, or absent; never half-written.

Every writer in nnfmu (datasets aside, which replace a whole folder) goes through
:func:`write_atomic`: the content is written to a temporary file beside the target,
``.<name>.<pid>.<random>.tmp<suffix>``, which is then renamed into place with
:func:`os.replace`, atomic on POSIX and Windows. The new file gets the old one's
permissions, or the usual ones (``0666`` less the umask) if there was none.

When the write fails, the temporary file and any folder created for the target
are removed, and an ``OSError`` becomes a :class:`~nnfmu.errors.DataFileError`
that names the target, the cause and what to do. A temporary file that a killed
process (SIGKILL, power loss) left behind is removed by the next write of the
same target, once its process is gone.
"""

from __future__ import annotations

import errno
import os
import re
import secrets
import stat
import sys
import time
from pathlib import Path
from typing import Callable

from nnfmu.errors import DataFileError

#: A temporary file of a writer that is not running (no pid to check) is stale after this many seconds.
STALE_AFTER_S = 3600.0

_OS_ERROR_HINTS = {  # by errno name (not every platform has every name)
    "ENOSPC": "free some disk space or choose another location",
    "EDQUOT": "free some of your disk quota or choose another location",
    "EFBIG": "the file system or a limit refuses a file this large; choose another location",
    "EROFS": "the file system is read-only; choose another location",
    "ENOTDIR": "a part of the path is a file, not a folder; choose another path",
    "EISDIR": "it is a folder; give the path of a file",
    "ENOENT": "check the path",
}


_PERMISSION_HINTS = {  # by what failed: a refused read is never fixed by writing elsewhere
    "write": "choose a location you may write to",
    "read": "check that you may read it and its folders",
    "either": "check the permissions of it and its folders",
}


def describe_os_error(exc: OSError, path: str | os.PathLike | None = None, *, doing: str = "either") -> str:
    """One line for ``exc``: the path (``path`` if given, else the error's own), the cause and what to do.

    ``doing``: ``"write"``, ``"read"`` or ``"either"`` (not known: a refused permission gets the fix that fits
    both), for the fix of a refused permission.
    """
    where = str(path) if path is not None else " -> ".join(str(f) for f in (exc.filename, exc.filename2) if f)
    cause = exc.strerror or str(exc)
    name = errno.errorcode.get(exc.errno, "")
    hint = _PERMISSION_HINTS[doing] if name in ("EACCES", "EPERM") else _OS_ERROR_HINTS.get(name)
    return f"{where + ': ' if where else ''}{cause}" + (f"; {hint}" if hint else "")


_SPECIAL = {stat.S_IFCHR: "a character device", stat.S_IFBLK: "a block device", stat.S_IFIFO: "a FIFO (named pipe)",
            stat.S_IFSOCK: "a socket"}


def through_link(path: str | os.PathLike) -> Path:
    """``path``, or where it points if it is a symbolic link: a write lands there and the link stays a link."""
    path = Path(path)
    return Path(os.path.realpath(path)) if path.is_symlink() else path


def resolve_target(path: str | os.PathLike) -> Path:
    """Where a write of ``path`` lands: the file a symbolic link points to, or ``path`` itself.

    Raises :class:`DataFileError` if that is a device node, a FIFO or a socket: renaming a file over one would
    destroy it (``/dev/full`` becoming a regular file, for root), and writing into one is not a file's write.
    """
    path = Path(path)
    target = through_link(path)
    try:
        kind = _SPECIAL.get(stat.S_IFMT(target.stat().st_mode))
    except OSError:
        return target  # absent (or unreadable): the write itself says why
    if kind:
        via = f" (the link {path} points to it)" if target != path else ""
        raise DataFileError(f"cannot write {target}{via}: it is {kind}, not a regular file; give the path of a file")
    return target


def _temp_pattern(path: Path, suffix: str) -> re.Pattern:
    return re.compile(rf"\.{re.escape(path.name)}\.(?:(?P<pid>\d+)\.)?[0-9a-z_]{{8}}\.tmp{re.escape(suffix)}")


def _pid_alive(pid: int) -> bool:
    if sys.platform == "win32":
        return True  # no cheap, safe check; such files age out instead
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except OSError:
        pass  # exists, owned by someone else
    try:  # a killed process that its parent has not reaped yet (a zombie) writes nothing any more
        return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0] != "Z"
    except (OSError, IndexError):
        return True


def remove_stale_temps(path: Path, suffix: str = "") -> list[Path]:
    """Remove temporary files of earlier writes of ``path`` whose writer is gone; return them."""
    pattern, removed = _temp_pattern(path, suffix), []
    try:
        candidates = [p for p in path.parent.iterdir() if pattern.fullmatch(p.name)]
    except OSError:
        return removed
    for candidate in candidates:
        match = pattern.fullmatch(candidate.name)
        pid = match.group("pid")
        try:
            stale = not _pid_alive(int(pid)) if pid else time.time() - candidate.stat().st_mtime > STALE_AFTER_S
            if stale:
                candidate.unlink()
                removed.append(candidate)
        except OSError:
            pass  # gone already, or not ours to remove
    return removed


def _make_parents(folder: Path) -> list[Path]:
    """Create ``folder`` and its missing parents; return those created, outermost first."""
    missing = []
    while not folder.exists() and folder != folder.parent:
        missing.append(folder)
        folder = folder.parent
    for f in reversed(missing):
        f.mkdir()
    return list(reversed(missing))


def _remove_empty(folders: list[Path]) -> None:
    for folder in reversed(folders):
        try:
            folder.rmdir()
        except OSError:
            break


def _create_temp(path: Path, suffix: str) -> Path:
    mode = path.stat().st_mode & 0o7777 if path.is_file() else 0o666  # 0o666 is masked by the umask
    for _ in range(100):
        tmp = path.parent / f".{path.name}.{os.getpid()}.{secrets.token_hex(4)}.tmp{suffix}"
        try:
            fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, "O_BINARY", 0), mode)
        except FileExistsError:
            continue
        os.close(fd)
        if path.is_file():
            os.chmod(tmp, mode)  # the umask applied at creation; keep the old file's permissions exactly
        return tmp
    raise FileExistsError(errno.EEXIST, "no free temporary file name", str(path))


def write_atomic(path: str | os.PathLike, write: Callable[[Path], None], suffix: str = "") -> Path:
    """Call ``write(tmp)`` on a temporary file beside ``path``, then rename it into place.

    ``suffix`` ends the temporary name (e.g. ``".npz"`` or ``".png"``) for writers that
    choose the format by extension. Missing parent folders are created. On any error,
    including Ctrl-C and SIGTERM, the temporary file and the folders created are removed
    and the exception propagates; an ``OSError`` propagates as :class:`DataFileError`
    naming ``path``. A symbolic link is written through (its target gets the content, the
    link stays); a device node, FIFO or socket is refused (:func:`resolve_target`).
    """
    path = resolve_target(path)
    created: list[Path] = []
    tmp = None
    try:
        created = _make_parents(path.parent)
        remove_stale_temps(path, suffix)
        tmp = _create_temp(path, suffix)
        write(tmp)
        os.replace(tmp, path)
    except BaseException as exc:
        if tmp is not None:
            tmp.unlink(missing_ok=True)
        _remove_empty(created)
        if isinstance(exc, OSError) and not isinstance(exc, DataFileError):
            raise DataFileError(f"cannot write {describe_os_error(exc, path, doing='write')}") from exc
        raise
    return path


def write_text_atomic(path: str | os.PathLike, text: str) -> Path:
    """Write ``text`` (UTF-8) to ``path`` atomically."""
    return write_atomic(path, lambda tmp: tmp.write_text(text, encoding="utf-8"))
