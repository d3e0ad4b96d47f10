"""Tables of signals read from CSV, MATLAB and NumPy files, and the column references that pick from them.

A :class:`Table` is one file seen as named columns, each a 1-D array of samples
(a MATLAB or NumPy file may hold variables of different lengths, e.g. one per split):

- CSV: a header row of names (optional: a file whose first row is numeric has
  none, and its columns are only addressed by index); the delimiter is ``,``
  ``;``, tab or white space.
- ``.mat`` (MATLAB v5 or v7.3) and ``.npz``: every numeric variable. A vector
  is one column named like the variable; a matrix ``X`` of shape ``(N, k)`` or
  ``(k, N)`` (time runs along the longer axis) gives the columns ``X[0]`` ..
  ``X[k-1]``, and the bare name ``X`` stands for all of them.

A reference (``ref``) to columns is a name, a ``X[j]`` column of a matrix, or a
0-based index into the table's columns (an ``int``, or a string of digits).
"""

from __future__ import annotations

import csv
import io
import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from nnfmu.errors import DataError, DataFileError

FORMATS = ("csv", "mat", "npz")
_SUFFIXES = {".csv": "csv", ".txt": "csv", ".tsv": "csv", ".dat": "csv", ".mat": "mat", ".npz": "npz"}


@dataclass(frozen=True)
class Table:
    """One file as named columns: ``columns[name]`` has shape ``(n_rows,)``; ``groups`` maps a matrix to its columns."""

    path: Path
    columns: dict[str, np.ndarray]
    groups: dict[str, tuple[str, ...]] = field(default_factory=dict)
    named: bool = True

    def resolve(self, ref) -> tuple[str, ...]:
        """The column names that ``ref`` stands for (one, or all columns of a matrix)."""
        names = list(self.columns)
        if isinstance(ref, (int, np.integer)) or (isinstance(ref, str) and ref.isdigit()):
            j = int(ref)
            if not 0 <= j < len(names):
                raise DataError(f"{self.path}: column index {j} is out of range; the file has {len(names)} "
                                f"columns (0 .. {len(names) - 1})")
            return (names[j],)
        if ref in self.columns:
            return (ref,)
        if ref in self.groups:
            return self.groups[ref]
        shown = ", ".join(list(self.groups) + [n for n in names if not any(n in g for g in self.groups.values())])
        raise DataError(f"{self.path} has no column {ref!r}; its columns are: {shown or ', '.join(names)}"
                        + ("" if self.named else " (it has no header row: give 0-based column indices)"))


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
        raise DataError(f"{path} holds no numeric columns")
    return table


def _read_csv(path: Path) -> Table:
    text = path.read_text(encoding="utf-8-sig", errors="replace")
    lines = [line for line in text.splitlines() if line.strip()]
    if not lines:
        raise DataFileError(f"{path} is empty; expected rows of numbers, optionally under a header row of names")
    delimiter = next((d for d in (",", ";", "\t") if d in lines[0]), None)
    split = (lambda s: next(csv.reader([s], delimiter=delimiter))) if delimiter else str.split
    first = [c.strip() for c in split(lines[0])]
    named = not all(_is_number(c) for c in first)
    body = lines[1:] if named else lines
    try:
        data = np.loadtxt(io.StringIO("\n".join(body)), delimiter=delimiter, ndmin=2, dtype=np.float64)
    except ValueError as exc:
        raise DataError(f"{path}: cannot read the rows as numbers ({exc}); every row below the header must hold "
                        "one number per column") from exc
    width = data.shape[1] if data.size else len(first)
    header = first if named else [str(j) for j in range(width)]
    if len(header) != width:
        raise DataError(f"{path}: the header names {len(header)} columns but the rows hold {width}")
    dup = sorted({h for h in header if header.count(h) > 1})
    if dup:
        raise DataError(f"{path}: column name(s) {dup} appear more than once in the header; rename them")
    return Table(path, {h: data[:, j] for j, h in enumerate(header)}, named=named)


def _is_number(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


def _read_mat_table(path: Path) -> Table:
    from nnfmu.data.loaders import _read_mat

    return _from_arrays(path, _read_mat(path))


def _read_npz(path: Path) -> Table:
    import zipfile

    try:
        with np.load(path, allow_pickle=False) as z:
            arrays = {k: z[k] for k in z.files}
    except (OSError, ValueError, zipfile.BadZipFile, EOFError) as exc:
        raise DataFileError(f"{path} cannot be read as .npz ({exc})") from exc
    return _from_arrays(path, arrays)


_SKIP = re.compile(r"^__")


def _from_arrays(path: Path, arrays: dict) -> Table:
    """Vectors become columns, matrices groups of columns ``X[j]``; other variables are left out."""
    columns, groups = {}, {}
    for name, value in arrays.items():
        a = np.asarray(value)
        if _SKIP.match(name) or a.dtype.kind not in "biuf" or a.ndim > 2 or a.size < 2:
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
    return Table(path, columns, groups)
