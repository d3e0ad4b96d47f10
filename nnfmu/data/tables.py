"""Tables of signals read from CSV, MATLAB and NumPy files, and the column references that pick from them.

A :class:`Table` is one file seen as named columns, each a 1-D array of samples
(a MATLAB or NumPy file may hold variables of different lengths, e.g. one per split):

- CSV: a header row of names (optional: a file whose first row is numeric has
  none, and its columns are only addressed by index); the delimiter is ``,``
  ``;``, tab or white space. Files are taken as benchmarks distribute them:
  empty fields at the end of a line (a trailing comma) are ignored, and only
  the columns a caller picks are converted to numbers, so an unused column may
  hold anything, and a column filled only in some rows (a sample rate given
  once in the first row) is read with :meth:`Table.setting`.
- ``.mat`` (MATLAB v5 or v7.3) and ``.npz``: every numeric variable. A vector
  is one column named like the variable; a matrix ``X`` of shape ``(N, k)`` or
  ``(k, N)`` (time runs along the longer axis) gives the columns ``X[0]`` ..
  ``X[k-1]``, and the bare name ``X`` stands for all of them. A single number
  is a setting (:meth:`Table.setting`), not a column.

A reference (``ref``) to columns is a name, a ``X[j]`` column of a matrix, or a
0-based index into the table's columns (an ``int``, or a string of digits).
Every position in a message is 0-based: column 0 is the first column, row 0
the first row below the header.
"""

from __future__ import annotations

import csv
import re
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from nnfmu.errors import DataError, DataFileError

FORMATS = ("csv", "mat", "npz")
_SUFFIXES = {".csv": "csv", ".txt": "csv", ".tsv": "csv", ".dat": "csv", ".mat": "mat", ".npz": "npz"}
_SETTING_RTOL = 1e-9  # the filled rows of a setting column must agree to this


@dataclass(frozen=True)
class Table:
    """One file as named columns: ``columns[name]`` has shape ``(n_rows,)``; ``groups`` maps a matrix to its columns.

    ``scalars`` holds single numbers of a .mat/.npz file (settings such as a sample rate) and
    ``unusable`` the variables that are no signal, each with the reason (not numeric, 3-D, ...).
    """

    path: Path
    columns: Mapping[str, np.ndarray]
    groups: dict[str, tuple[str, ...]] = field(default_factory=dict)
    named: bool = True
    scalars: dict[str, float] = field(default_factory=dict)
    unusable: dict[str, str] = field(default_factory=dict)

    def resolve(self, ref) -> tuple[str, ...]:
        """The column names that ``ref`` stands for (one, or all columns of a matrix)."""
        names = list(self.columns)
        if isinstance(ref, (int, np.integer)) or (isinstance(ref, str) and ref.isdigit()):
            j = int(ref)
            if not 0 <= j < len(names):
                raise DataError(f"{self.path}: column index {j} is out of range; the file has {len(names)} "
                                f"columns (0 .. {len(names) - 1}, 0-based)")
            return (names[j],)
        if ref in self.columns:
            return (ref,)
        if ref in self.groups:
            return self.groups[ref]
        if ref in self.unusable:
            raise DataError(f"{self.path}: {ref!r} {self.unusable[ref]}, not a numeric signal; save it as a "
                            f"float vector or (N, k) matrix, e.g. np.asarray({ref}, dtype=float)")
        if ref in self.scalars:
            raise DataError(f"{self.path}: {ref!r} holds a single number ({self.scalars[ref]:g}), not a signal; "
                            "if it is the sample time or rate, read it with Ts_column/fs_column (CLI: --Ts-column, "
                            "--fs-column)")
        shown = ", ".join(list(self.groups) + [n for n in names if not any(n in g for g in self.groups.values())])
        raise DataError(f"{self.path} has no column {ref!r}; its columns are: {shown or ', '.join(names)}"
                        + ("" if self.named else " (it has no header row: give 0-based column indices)"))

    def setting(self, ref) -> float:
        """A value given once: a single number of a .mat/.npz file, or a column filled in some rows only.

        The filled rows must agree; an empty CSV field or a NaN is a row left empty.
        """
        if not isinstance(ref, (int, np.integer)) and ref in self.scalars:
            return self.scalars[ref]
        names = self.resolve(ref)
        if len(names) != 1:
            raise DataError(f"{self.path}: {ref!r} is a matrix of {len(names)} columns; name one column")
        (name,) = names
        numbers = getattr(self.columns, "numbers", None)
        values = numbers(name, empty=np.nan) if numbers else np.asarray(self.columns[name], dtype=np.float64)
        filled = values[~np.isnan(values)]
        if not len(filled):
            raise DataError(f"{self.path}: column {name!r} is empty in every row; name the column that holds "
                            "the value")
        if np.abs(filled - filled[0]).max() > _SETTING_RTOL * abs(filled[0]):
            rows = np.flatnonzero(~np.isnan(values))
            odd = int(rows[np.flatnonzero(np.abs(filled - filled[0]) > _SETTING_RTOL * abs(filled[0]))[0]])
            raise DataError(f"{self.path}: column {name!r} should hold one value, but row {int(rows[0])} holds "
                            f"{filled[0]:g} and row {odd} {values[odd]:g} (0-based rows); name the column that "
                            "holds the setting")
        return float(filled[0])


def format_of(path: Path, fmt: str | None = None) -> str:
    """``fmt`` if given, else the format of ``path``'s suffix (.csv/.txt/.tsv/.dat, .mat, .npz)."""
    if fmt is not None:
        if fmt not in FORMATS:
            raise DataError(f"unknown file format {fmt!r}; choose one of {', '.join(FORMATS)}")
        return fmt
    try:
        return _SUFFIXES[path.suffix.lower()]
    except KeyError:
        raise DataError(f"cannot tell the format of {path} from its suffix; name it (csv, mat or npz)") from None


def read_table(path, fmt: str | None = None) -> Table:
    """Read ``path`` as a :class:`Table` (``fmt``: 'csv', 'mat' or 'npz'; default: by suffix)."""
    path = Path(path)
    fmt = format_of(path, fmt)
    if not path.is_file():
        raise DataFileError(f"{path} not found; give the path of a {fmt} file")
    table = {"csv": _read_csv, "mat": _read_mat_table, "npz": _read_npz}[fmt](path)
    if not table.columns:
        detail = "; ".join(f"{k!r} {v}" for k, v in table.unusable.items())
        raise DataError(f"{path} holds no numeric columns" + (f" ({detail})" if detail else ""))
    return table


class _CsvColumns(Mapping):
    """The columns of a CSV file, converted to numbers when first asked for (shape ``(n_rows,)``, float64)."""

    def __init__(self, path: Path, names: list[str], rows: list[list[str]]):
        self.path, self.names, self.rows, self.cache = path, names, rows, {}
        self.index = {n: j for j, n in enumerate(names)}

    def __len__(self) -> int:
        return len(self.names)

    def __iter__(self):
        return iter(self.names)

    def __contains__(self, name) -> bool:  # Mapping's own would convert the column
        return name in self.index

    def __getitem__(self, name: str) -> np.ndarray:
        if name not in self.cache:
            self.cache[name] = self.numbers(name)
        return self.cache[name]

    def numbers(self, name: str, empty: float | None = None) -> np.ndarray:
        """Column ``name`` as float64; an empty field becomes ``empty`` (None: an error naming its row)."""
        j = self.index[name]
        fields = [row[j].strip() if j < len(row) else "" for row in self.rows]
        if empty is not None:
            fields = [f if f else repr(empty) for f in fields]
        try:
            return np.array(fields, dtype=np.float64)
        except ValueError:
            pass
        i, bad = next((i, f) for i, f in enumerate(fields) if not _is_number(f))
        what = "is empty" if not bad else f"holds {bad!r}, not a number"
        filled = sum(1 for f in fields if f)
        hint = (f"; the column is filled in {filled} of {len(fields)} rows: if it holds the sample time or rate, "
                "read it as a setting (Ts_column/fs_column; CLI: --Ts-column/--fs-column)"
                if not bad and filled < len(fields) / 2 else "; every row of a picked column must hold a number")
        raise DataError(f"{self.path}: row {i}, column {j} ({name!r}) {what} (0-based positions, row 0 is the "
                        f"first row below the header){hint}")


def _split_rows(path: Path, lines: list[str]) -> list[list[str]]:
    delimiter = next((d for d in (",", ";", "\t") if d in lines[0]), None)
    rows = list(csv.reader(lines, delimiter=delimiter)) if delimiter else [line.split() for line in lines]
    for row in rows:  # a trailing delimiter leaves empty fields at the end: not columns
        while row and not row[-1].strip():
            row.pop()
    return rows


def _read_csv(path: Path) -> Table:
    text = path.read_text(encoding="utf-8-sig", errors="replace")
    lines = [line for line in text.splitlines() if line.strip()]
    if not lines:
        raise DataFileError(f"{path} is empty; expected rows of numbers, optionally under a header row of names")
    rows = _split_rows(path, lines)
    first = [c.strip() for c in rows[0]]
    named = not all(_is_number(c) for c in first)
    body = rows[1:] if named else rows
    if not body:
        raise DataError(f"{path} has a header row but no rows of data below it; give a file with at least two "
                        "rows of samples")
    width = max(len(r) for r in body)
    if named and width > len(first):
        i = next(i for i, r in enumerate(body) if len(r) > len(first))
        raise DataError(f"{path}: the header names {len(first)} columns but row {i} (0-based, below the header) "
                        f"holds {len(body[i])} fields; give every column a name, or remove the extra fields")
    header = [h or f"column_{j}" for j, h in enumerate(first)] if named else [str(j) for j in range(width)]
    dup = sorted({h for h in header if header.count(h) > 1})
    if dup:
        raise DataError(f"{path}: column name(s) {dup} appear more than once in the header; rename them")
    return Table(path, _CsvColumns(path, header, body), named=named)


def _is_number(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


def _read_mat_table(path: Path) -> Table:
    return _from_arrays(path, read_mat(path))


def read_mat(path: Path) -> dict[str, np.ndarray]:
    """Read a MATLAB file, v5 (scipy) or v7.3 (HDF5, transposed on disk)."""
    import scipy.io

    if not path.is_file():
        raise DataFileError(f"{path} not found; give the path of an existing .mat file")
    try:
        raw = scipy.io.loadmat(path)
        return {k: np.asarray(v) for k, v in raw.items() if not k.startswith("__")}
    except NotImplementedError:  # MATLAB v7.3 is HDF5
        import h5py

        with h5py.File(path, "r") as f:
            return {k: np.asarray(f[k]).T for k in f.keys() if isinstance(f[k], h5py.Dataset)}
    except (ValueError, OSError, TypeError, scipy.io.matlab.MatReadError) as exc:
        raise DataFileError(f"{path} is not a readable MATLAB .mat file ({exc})") from exc


def _read_npz(path: Path) -> Table:
    import zipfile

    arrays, unusable = {}, {}
    try:
        with np.load(path, allow_pickle=False) as z:
            for k in z.files:
                try:
                    arrays[k] = z[k]
                except ValueError:  # an object array: only readable by unpickling, which could run code
                    unusable[k] = "is an array of Python objects (dtype object)"
    except (OSError, ValueError, zipfile.BadZipFile, EOFError) as exc:
        raise DataFileError(f"{path} cannot be read as .npz ({exc})") from exc
    table = _from_arrays(path, arrays)
    table.unusable.update(unusable)
    return table


_SKIP = re.compile(r"^__")


def _from_arrays(path: Path, arrays: dict) -> Table:
    """Vectors become columns, matrices groups of columns ``X[j]``, single numbers scalars; the rest is unusable."""
    columns, groups, scalars, unusable = {}, {}, {}, {}
    for name, value in arrays.items():
        if _SKIP.match(name):
            continue
        a = np.asarray(value)
        if a.dtype.kind not in "biuf":
            unusable[name] = f"holds {'text' if a.dtype.kind in 'SU' else f'values of dtype {a.dtype}'}"
            continue
        if a.size == 1:
            scalars[name] = float(a.ravel()[0])
            continue
        if a.ndim > 2 or a.size < 2:
            unusable[name] = f"has shape {a.shape}"
            continue
        a = a.astype(np.float64)
        if a.ndim == 2 and min(a.shape) == 1:
            a = a.ravel()
        if a.ndim == 1:
            columns[name] = a
            continue
        a = a if a.shape[0] >= a.shape[1] else a.T  # time along the longer axis
        groups[name] = tuple(f"{name}[{j}]" for j in range(a.shape[1]))
        columns.update({f"{name}[{j}]": np.ascontiguousarray(a[:, j]) for j in range(a.shape[1])})
    return Table(path, columns, groups, scalars=scalars, unusable=unusable)
