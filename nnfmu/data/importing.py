"""Measured data from CSV, MATLAB and NumPy files as a :class:`~nnfmu.data.Dataset` (``nnfmu import csv|mat|npz``).

Each file holds one trajectory per split it serves; the columns are picked by
name or 0-based index (:mod:`nnfmu.data.tables`). The splits come either from
separate files (``files={"train": [...], "test": [...]}``) or from other
columns of the same files (``columns={"test": ["uVal", "yVal"]}``), or both.
A dataset needs a test split: without one, :func:`load_files` refuses, and it
refuses a test or validation split that reads exactly the training columns of
the training files. Nothing is read twice and nothing is written here; the
caller saves the finished dataset (atomically) with :func:`~nnfmu.data.save_dataset`.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path
from typing import Mapping, Sequence

import numpy as np

from nnfmu.data.dataset import SPLIT_NAMES, Dataset, make_trajectories
from nnfmu.data.resample import decimate
from nnfmu.data.sampling import sample_time
from nnfmu.data.tables import Table, format_of, read_table
from nnfmu.errors import DataError
from nnfmu.identifiers import to_c_identifier

NO_TEST = ("no test split: every model is scored on held-out test data. Give test files (Python: "
           "files={'train': ..., 'test': ...}; CLI: --test FILE...) or the test columns of the same files "
           "(Python: columns={'test': [...]}; CLI: --test-columns COL,...)")


@dataclass(frozen=True)
class Entry:
    """One item of ``inputs``/``outputs``: column(s) ``ref`` and the channel ``name`` (or prefix) they get."""

    name: str | None
    ref: str | int

    @property
    def key(self) -> str:
        return self.name if self.name is not None else str(self.ref)


def entries(spec, what: str) -> tuple[Entry, ...]:
    """``["a", 3]``, ``[("name", "col"), ...]`` or ``{"name": "col"}`` as entries."""
    if isinstance(spec, (str, int)):
        spec = [spec]
    items = list(spec.items()) if isinstance(spec, Mapping) else list(spec or ())
    out = []
    for item in items:
        name, ref = item if isinstance(item, tuple) else (None, item)
        if not isinstance(ref, (str, int)) or (name is not None and not isinstance(name, str)):
            raise DataError(f"{what}: expected column names or indices (or name -> column pairs), got {item!r}")
        out.append(Entry(name, ref))
    if not out:
        raise DataError(f"no {what} given; name at least one column (by name or 0-based index)")
    return tuple(out)


def _file_lists(files) -> dict[str, list[Path]]:
    if isinstance(files, (str, os.PathLike)) or (isinstance(files, Sequence) and not isinstance(files, Mapping)):
        files = {"train": files}
    out = {}
    for split, group in dict(files).items():
        if split not in SPLIT_NAMES:
            raise DataError(f"unknown split {split!r}; splits are {', '.join(SPLIT_NAMES)}")
        group = [group] if isinstance(group, (str, os.PathLike)) else list(group)
        if not group:
            raise DataError(f"no files given for the {split} split")
        out[split] = [Path(f) for f in group]
    if "train" not in out:
        raise DataError("no training files given; name the files that hold the training data")
    return out


def _override(base: tuple[Entry, ...], given, split: str) -> tuple[Entry, ...]:
    """The entries of a split with its own columns: positional (same order as inputs then outputs) or by key."""
    if isinstance(given, Mapping):
        keys = {e.key for e in base}
        unknown = sorted(set(given) - keys)
        if unknown:
            raise DataError(f"{split} columns: {unknown} name no input or output; use the names of --inputs "
                            f"and --outputs: {sorted(keys)}")
        return tuple(Entry(e.name, given.get(e.key, e.ref)) if e.key in given else e for e in base)
    refs = [given] if isinstance(given, (str, int)) else list(given)
    if len(refs) != len(base):
        raise DataError(f"{split} columns: got {len(refs)} column(s) for {len(base)} input and output entries; "
                        "give one per entry, inputs first, or map them by name (name=column)")
    return tuple(Entry(e.name, r) for e, r in zip(base, refs))


def _identifier(text: str) -> str:
    return to_c_identifier(text, prefix="c_")


def _channel_names(table: Table, entry: Entry, columns: tuple[str, ...], role: str, position: int) -> list[str]:
    if entry.name is not None:
        return [entry.name] if len(columns) == 1 else [f"{entry.name}{j + 1}" for j in range(len(columns))]
    if len(columns) > 1:
        return [f"{_identifier(str(entry.ref))}{j + 1}" for j in range(len(columns))]
    if isinstance(entry.ref, int) or str(entry.ref).isdigit():
        return [_identifier(columns[0])] if table.named else [f"{role}{position + 1}"]
    return [_identifier(columns[0])]


class _Reader:
    """Reads every file once and picks the columns of one split's trajectories."""

    def __init__(self, fmt: str | None):
        self.fmt, self.tables = fmt, {}

    def table(self, path: Path) -> Table:
        key = path.resolve()
        if key not in self.tables:
            self.tables[key] = read_table(path, self.fmt)
        return self.tables[key]

    def columns(self, path: Path, ents: tuple[Entry, ...]) -> list[tuple[str, ...]]:
        table = self.table(path)
        return [table.resolve(e.ref) for e in ents]


def _stack(table: Table, cols: list[tuple[str, ...]], where: str) -> np.ndarray:
    flat = [c for group in cols for c in group]
    lengths = {len(table.columns[c]) for c in flat}
    if len(lengths) > 1:
        raise DataError(f"{where}: the columns {flat} have different lengths {sorted(lengths)}; the columns of one "
                        "trajectory must be sampled at the same instants")
    return np.column_stack([table.columns[c] for c in flat])


def load_files(
    files,
    *,
    inputs,
    outputs,
    columns: Mapping | None = None,
    units: Mapping[str, str] | Sequence[str] | None = None,
    Ts: float | None = None,
    time_column: str | int | None = None,
    Ts_column: str | int | None = None,
    fs_column: str | int | None = None,
    resample: int = 1,
    valid_fraction: float | None = None,
    valid_trajectories: int | None = None,
    seed: int = 0,
    fmt: str | None = None,
) -> Dataset:
    """Build a dataset from CSV, ``.mat`` or ``.npz`` files; each file is one trajectory of its split.

    Parameters
    ----------
    files : path, list of paths, or dict split -> path(s)
        A path or a list holds the training files; a dict names the files of each split
        (``train``, ``valid``, ``test``). A split named in ``columns`` but not here reads the
        training files.
    inputs, outputs : list of column references, or dict channel name -> reference
        References are column names, 0-based indices, or a matrix variable of a .mat/.npz file
        (all its columns). The channel names default to the column names (made identifiers).
    columns : dict split -> list or dict of references, optional
        The columns a split reads instead of those of ``inputs`` and ``outputs``: a list in their
        order (inputs first), or a dict keyed by channel name (or original reference).
        ``columns={"test": ["uVal", "yVal"]}`` reads the test split from other columns.
    units : dict channel name -> unit, or a list (inputs then outputs), optional
    Ts, time_column, Ts_column, fs_column : the sample time, one of the four
        ``Ts`` in s; or ``time_column``, time stamps in s (Ts is their median step, rounded to the
        decimals the stamps carry, :func:`~nnfmu.data.sampling.measured_step`); or ``Ts_column``
        (in s) or ``fs_column`` (in Hz), a setting given once: a column filled in some rows only (the
        F-16 benchmark's ``Fs``, in its first row) or a single number of a .mat/.npz file. Files whose
        sample times agree to 1e-4 (relative) share the training files' median; Ts forces one.
    resample : int
        Keep every ``resample``-th sample after an anti-aliasing filter (:mod:`nnfmu.data.resample`);
        the dataset's Ts is ``resample`` times the files'.
    valid_fraction, valid_trajectories : optional
        Carve the validation split out of train (see :meth:`Dataset.with_validation`) unless
        validation files or columns are given.
    seed : seeds the choice of validation trajectories.
    fmt : 'csv', 'mat' or 'npz'; default by each file's suffix.

    Raises
    ------
    DataError
        With no test split (the message says how to give one), a test or validation split that
        reads the training columns of the training files, missing columns, or bad numbers.
    """
    file_lists = _file_lists(files)
    columns = dict(columns or {})
    for split in columns:
        if split not in SPLIT_NAMES:
            raise DataError(f"columns: unknown split {split!r}; splits are {', '.join(SPLIT_NAMES)}")
    splits = [s for s in SPLIT_NAMES if s in file_lists or s in columns]
    if "test" not in splits:
        raise DataError(NO_TEST)
    carve = valid_fraction is not None or valid_trajectories is not None
    if carve and "valid" in splits:
        raise DataError("give the validation split either as files or columns, or as a share of train "
                        "(fraction or number of trajectories), not both")
    input_entries = entries(inputs, "inputs")
    base, n_in = input_entries + entries(outputs, "outputs"), len(input_entries)
    reader = _Reader(None if fmt is None else format_of(Path(), fmt))
    notes: list = []
    Ts_files = sample_time(reader, file_lists, {"Ts": Ts, "time_column": time_column, "Ts_column": Ts_column,
                                                 "fs_column": fs_column}, notes)
    first = file_lists["train"][0]
    names = _names(reader.table(first), base, reader.columns(first, base), n_in)
    seen: dict = {}
    data = {split: _read_split(reader, split, file_lists.get(split, file_lists["train"]),
                               _override(base, columns[split], split) if split in columns else base,
                               names, resample, seen) for split in splits}
    source = _source(file_lists, columns, splits, reader, base, resample, Ts_files)
    if notes:
        source["notes"] = notes
    Ts = Ts_files if resample == 1 else float(f"{Ts_files * resample:.15g}")  # 3 x 0.1: 0.3, not 0.30000000000000004
    ds = Dataset(Ts=Ts, inputs=tuple(names[0]), outputs=tuple(names[1]), splits=data,
                 source=source).with_units(units)
    if carve:
        ds = ds.with_validation(valid_fraction, seed=seed, n_traj=valid_trajectories)
    return ds


def _read_split(reader: _Reader, split: str, paths: list[Path], ents: tuple[Entry, ...],
                names: tuple[list[str], list[str]], resample: int, seen: dict):
    """One split's trajectories, one per file; ``seen`` maps (file, columns) to the split that read them."""
    n_u, n_y = len(names[0]), len(names[1])
    us, ys = [], []
    for path in paths:
        cols = reader.columns(path, ents)
        key = (path.resolve(), tuple(c for g in cols for c in g))
        if seen.get(key, split) != split:
            raise DataError(f"the {split} split would read the same columns of {path} as the {seen[key]} split; "
                            f"give it its own columns (columns={{'{split}': [...]}}, CLI --{split}-columns) or its "
                            "own files")
        seen[key] = split
        where = f"{path} ({split})"
        table = _stack(reader.table(path), cols, where)
        if table.shape[1] != n_u + n_y:
            raise DataError(f"{where}: the columns {list(key[1])} give {table.shape[1]} channels, expected {n_u} "
                            f"inputs and {n_y} outputs as in the training files")
        if len(table) < 2:
            raise DataError(f"{where} has {len(table)} row(s) of samples; a trajectory needs at least 2")
        table = decimate(table, resample, where)
        us.append(table[:, :n_u])
        ys.append(table[:, n_u:])
    return make_trajectories(us, ys, split)


def _names(table: Table, base: tuple[Entry, ...], cols: list, n_in: int) -> tuple[list[str], list[str]]:
    ins, outs = [], []
    for i, (e, c) in enumerate(zip(base, cols)):
        role, target = ("u", ins) if i < n_in else ("y", outs)
        target.extend(_channel_names(table, e, c, role, len(target)))
    return ins, outs


def _source(file_lists, columns, splits, reader, base, resample: int, Ts_files: float) -> dict:
    files = {s: [str(p.resolve()) for p in file_lists.get(s, file_lists["train"])] for s in splits}
    formats = sorted({format_of(p, reader.fmt) for g in file_lists.values() for p in g})
    source = {"kind": "import", "name": _identifier(file_lists["train"][0].stem), "format": formats, "files": files,
              "columns": {s: [str(e.ref) for e in (_override(base, columns[s], s) if s in columns else base)]
                          for s in splits}}
    if resample > 1:
        source["resampled"] = {"factor": resample, "original_Ts": Ts_files,
                               "filter": "FIR low-pass (firwin, Hamming, 10q+1 taps per stage of at most 10), "
                                         "run forward and backward (filtfilt, zero phase)"}
    return source
