"""The dataset folder on disk (docs/design.md, "Dataset on disk").

    DIR/meta.json    Ts, inputs and outputs ({name, unit}), source, split lengths, init_window (optional)
    DIR/train.npz    u (n_traj, n_steps, n_u), y (n_traj, n_steps, n_y), lengths (n_traj,)
    DIR/valid.npz    optional, same layout
    DIR/test.npz     same layout

Trajectories shorter than the longest are padded with NaN after their last
sample, and ``lengths`` says where each ends. The loader cuts the padding off,
so it never reaches statistics, training or scores, and a NaN inside a
trajectory's own samples is still reported as bad data.

Writing is atomic: the folder is built under a temporary name beside the
target, ``.<name>.<pid>.<random>.tmp``, and renamed into place, so a failure
leaves no half-written dataset. A temporary folder that a killed process left
behind is removed by the next save of the same target (:func:`remove_stale_temp_dirs`).
"""

from __future__ import annotations

import errno
import json
import os
import secrets
import shutil
import time
import zipfile
from pathlib import Path

import numpy as np

from nnfmu.atomic import describe_os_error, through_link
from nnfmu.data.dataset import SPLIT_NAMES, Dataset, Trajectories, _check_split
from nnfmu.errors import DataError, DataFileError, ShapeError


def save_dataset(ds: Dataset, path: str | os.PathLike, *, overwrite: bool = False) -> Path:
    """Write ``ds`` as a dataset folder at ``path`` and return the path.

    An existing folder is replaced only with ``overwrite=True``, and only if it
    is a dataset folder (:func:`check_replaceable`); the old one stays intact
    until the new one is complete. A symbolic link is written through to its
    folder. A dataset without a ``test`` split is refused (:class:`DataError`):
    every model is scored on it.
    """
    path = through_link(path)
    if "test" not in ds.splits:
        raise DataError(f"the dataset has no 'test' split (it has {', '.join(ds.splits)}), so nothing could be "
                        f"scored on {path}; add held-out test data: from_arrays(u_test=..., y_test=...), "
                        "load_csv(..., columns={'test': [...]}) or files={'test': ...}, or "
                        "ds.replace(splits={**ds.splits, 'test': ...})")
    if path.exists() and not overwrite:
        raise DataFileError(
            f"{path} already exists; choose another folder or pass overwrite=True (CLI: --force)"
        )
    check_replaceable(path)
    parent = path.resolve().parent
    try:
        parent.mkdir(parents=True, exist_ok=True)
        remove_stale_temp_dirs(path)
        tmp = _make_temp_dir(parent / f".{path.name}.{os.getpid()}")
    except OSError as exc:
        raise _write_error(exc, path) from exc
    try:
        for name, tr in ds.splits.items():
            _write_split(tmp / f"{name}.npz", tr)
        (tmp / "meta.json").write_text(json.dumps(ds.meta(), indent=2) + "\n")
        _replace_dir(tmp, path)
    except BaseException as exc:
        shutil.rmtree(tmp, ignore_errors=True)
        if isinstance(exc, OSError) and not isinstance(exc, DataFileError):
            raise _write_error(exc, path) from exc
        raise
    return path


#: What a dataset folder holds; replacing a folder that holds anything else would lose it.
DATASET_FILES = frozenset({"meta.json", *(f"{name}.npz" for name in SPLIT_NAMES)})


def check_replaceable(path: str | os.PathLike) -> None:
    """Raise :class:`DataFileError` unless ``path`` is absent, an empty folder or a dataset folder.

    A dataset folder holds ``meta.json`` and nothing but the files of :data:`DATASET_FILES`. Anything else
    (a file, a folder of the user's own work) is named in the message and never replaced, even with
    ``--force``.
    """
    path = through_link(path)
    if not path.exists():
        return
    if not path.is_dir():
        raise DataFileError(f"{path} is a file, not a dataset folder; nnfmu replaces only a dataset folder it "
                            "wrote: choose another folder")
    try:
        entries = sorted(path.iterdir())
    except OSError as exc:
        raise _write_error(exc, path) from exc
    foreign = [e.name for e in entries if e.name not in DATASET_FILES or not e.is_file() or e.is_symlink()]
    if foreign:
        more = f" and {len(foreign) - 3} more" if len(foreign) > 3 else ""
        what = f"it holds {', '.join(map(repr, foreign[:3]))}{more}, which nnfmu did not write"
    elif entries and not (path / "meta.json").is_file():
        what = "it has no meta.json"
    else:
        return
    raise DataFileError(f"{path} is not a dataset folder: {what}; --force replaces only a dataset folder: move "
                        "those files away or choose another folder")


def _make_temp_dir(stem: Path) -> Path:
    """A new folder ``<stem>.<random>.tmp``, with the usual permissions (``0777`` less the umask), as any folder the
    user makes: :func:`tempfile.mkdtemp` makes it ``0700``, and the dataset folder would keep that."""
    for _ in range(100):
        tmp = stem.with_name(f"{stem.name}.{secrets.token_hex(4)}.tmp")
        try:
            tmp.mkdir()
            return tmp
        except FileExistsError:
            continue
    raise FileExistsError(errno.EEXIST, "no free temporary folder name", str(stem))


def _write_error(exc: OSError, path: Path) -> DataFileError:
    """One line: the folder, the cause, what to do (a full disk: free space or write elsewhere)."""
    if exc.errno in (errno.ENOSPC, getattr(errno, "EDQUOT", errno.ENOSPC)):
        return DataFileError(f"no space left on device at {path}; free space or choose another folder "
                             "(CLI: another -o)")
    return DataFileError(f"cannot write the dataset folder {describe_os_error(exc, path, doing='write')}")


def remove_stale_temp_dirs(path: Path) -> list[Path]:
    """Remove the temporary folders of earlier saves of ``path`` that were abandoned; return them.

    A save builds ``.<name>.<pid>.<random>.tmp`` beside ``path``. One is abandoned when its
    process is gone (killed by SIGKILL or a power loss); one without a pid (written before the
    pid was part of the name) when it is older than :data:`nnfmu.atomic.STALE_AFTER_S`. A
    folder of a save still running, or of another name, is never touched.
    """
    from nnfmu.atomic import STALE_AFTER_S, _pid_alive, _temp_pattern

    pattern, removed = _temp_pattern(path, ""), []
    try:
        candidates = [p for p in path.parent.iterdir() if pattern.fullmatch(p.name)]
    except OSError:
        return removed
    for candidate in candidates:
        pid = pattern.fullmatch(candidate.name).group("pid")
        try:
            if candidate.is_symlink() or not candidate.is_dir():
                continue
            if (not _pid_alive(int(pid))) if pid else time.time() - candidate.stat().st_mtime > STALE_AFTER_S:
                shutil.rmtree(candidate)
                removed.append(candidate)
        except OSError:
            pass  # gone already, or not ours to remove
    return removed


def _write_split(file: Path, tr: Trajectories) -> None:
    n_max = int(tr.lengths.max())
    u = np.full((tr.n_traj, n_max, tr.u[0].shape[1]), np.nan)
    y = np.full((tr.n_traj, n_max, tr.y[0].shape[1]), np.nan)
    for i, (ui, yi) in enumerate(zip(tr.u, tr.y)):
        u[i, :len(ui)] = ui
        y[i, :len(yi)] = yi
    with open(file, "wb") as f:
        np.savez_compressed(f, u=u, y=y, lengths=tr.lengths)


def _replace_dir(new: Path, target: Path) -> None:
    if not target.exists():
        os.replace(new, target)
        return
    old = target.with_name(f".{target.name}.old")
    shutil.rmtree(old, ignore_errors=True)
    os.replace(target, old)
    try:
        os.replace(new, target)
    except OSError:
        os.replace(old, target)
        raise
    shutil.rmtree(old, ignore_errors=True)


def load_dataset(path: str | os.PathLike) -> Dataset:
    """Read a dataset folder written by :func:`save_dataset` (or by hand in that layout)."""
    path = Path(path)
    if not path.is_dir():
        hint = " (it is a file; give the folder that holds meta.json)" if path.exists() else ""
        raise DataFileError(f"dataset folder {path} not found{hint}; create one with `nnfmu generate` "
                            "or `nnfmu import`")
    meta = _read_meta(path / "meta.json")
    n_u, n_y = len(meta["inputs"]), len(meta["outputs"])
    splits = {}
    for name in SPLIT_NAMES:
        file = path / f"{name}.npz"
        if file.exists():
            splits[name] = _read_split(file, n_u, n_y)
            _check_split(splits[name], name, n_u, n_y, f"{file}: ")
    if not splits:
        raise DataFileError(f"{path} holds no split; expected train.npz and test.npz beside meta.json")
    try:
        return Dataset(Ts=meta["Ts"], inputs=meta["inputs"], outputs=meta["outputs"],
                       splits=splits, source=meta.get("source", {}), init_window=meta.get("init_window"))
    except (DataError, ShapeError) as exc:
        raise type(exc)(f"{path}: {exc}") from exc


def _read_meta(file: Path) -> dict:
    try:
        meta = json.loads(file.read_text())
    except FileNotFoundError as exc:
        raise DataFileError(f"{file} not found; a dataset folder needs meta.json") from exc
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise DataFileError(f"{file} is not valid JSON ({exc}); rewrite it or regenerate the dataset") from exc
    missing = [k for k in ("Ts", "inputs", "outputs") if k not in meta]
    if missing:
        raise DataFileError(f"{file} lacks the key(s) {missing}; it needs Ts, inputs and outputs")
    return meta


def _read_split(file: Path, n_u: int, n_y: int) -> Trajectories:
    try:
        with np.load(file, allow_pickle=False) as z:
            arrays = {k: z[k] for k in z.files}
    except (OSError, ValueError, zipfile.BadZipFile, EOFError) as exc:
        raise DataFileError(f"{file} cannot be read as .npz ({exc}); regenerate or re-import it") from exc
    for key in ("u", "y"):
        if key not in arrays:
            raise DataFileError(f"{file} has no array {key!r} (it has {sorted(arrays)})")
    u, y = arrays["u"], arrays["y"]
    for var, arr, n in (("u", u, n_u), ("y", y, n_y)):
        if arr.ndim != 3 or arr.shape[2] != n:
            raise ShapeError(f"{file}: array {var!r} has shape {arr.shape}, expected (n_traj, n_steps, {n}) "
                             f"to match the {n} channels named in meta.json")
    if u.shape[:2] != y.shape[:2]:
        raise ShapeError(f"{file}: arrays 'u' {u.shape} and 'y' {y.shape} disagree in (n_traj, n_steps)")
    lengths = arrays.get("lengths", np.full(u.shape[0], u.shape[1]))
    if lengths.shape != (u.shape[0],) or (lengths > u.shape[1]).any() or (lengths < 0).any():
        raise ShapeError(f"{file}: array 'lengths' {lengths.tolist()} does not fit arrays of shape {u.shape}")
    return Trajectories(tuple(u[i, :n] for i, n in enumerate(lengths)),
                        tuple(y[i, :n] for i, n in enumerate(lengths)))

