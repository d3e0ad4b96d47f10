"""The sample time of imported records: measured from a time column, read from a setting, agreed across files.

- :func:`measured_step`: a time column's median step, refused when the steps vary by more than
  1 %, and rounded to what the column resolves. Time stamps written with 4 decimals give a step
  with 4 decimals: ``0.1`` rather than the ``0.09999999999994458`` that subtracting ``1000.1 - 1000.0``
  leaves in binary floating point.
  A step of more than 6 significant digits gives the roundest Ts within :data:`AGREE_RTOL`.
- :func:`sample_time`: the files' Ts from one of the timing options, or from a column named ``Ts``, ``fs`` or
  ``time`` when none is given.
- :func:`common_sample_time`: records whose sample times agree to :data:`AGREE_RTOL` (relative)
  are one dataset; its Ts is the training records' median. Measured records of one benchmark differ
  in the last digits (the two EMPS axis files by 0.0024 %); a larger difference is refused with
  the way out (force one Ts, or resample).
"""

from __future__ import annotations

from typing import Mapping

import numpy as np

from nnfmu.errors import DataError

#: Records whose sample times differ by no more than this (relative) share one Ts.
AGREE_RTOL = 1e-4
#: A time column whose steps differ from their median by more than this (relative) is not uniformly sampled.
UNIFORM_RTOL = 0.01
_ROUND_RTOL = 1e-6  # rounding to the column's resolution never moves Ts by more than this (relative)


def resolution(t: np.ndarray) -> int | None:
    """The fewest decimals (0 .. 15) that represent every time stamp of ``t`` (s) to float precision, or None."""
    t = np.asarray(t, dtype=np.float64)
    t = t[np.isfinite(t)]
    if not len(t):
        return None
    tol = 16 * np.finfo(np.float64).eps * max(float(np.abs(t).max()), np.finfo(np.float64).tiny)
    for decimals in range(16):
        if np.all(np.abs(t - np.round(t, decimals)) <= tol):
            return decimals
    return None


def round_to_resolution(Ts: float, t: np.ndarray) -> float:
    """``Ts`` rounded to the decimals that the time stamps ``t`` resolve, if that moves it by float noise only."""
    decimals = resolution(t)
    if decimals is None:
        return float(Ts)
    rounded = round(float(Ts), decimals)
    return rounded if rounded > 0 and abs(rounded - Ts) <= _ROUND_RTOL * Ts else float(Ts)


def snap(Ts: float) -> float:
    """The roundest value (fewest significant digits, up to 3) within :data:`AGREE_RTOL` of ``Ts``, else ``Ts``:
    a 1 kHz record's time vector steps 0.0009999839611 s, which is 0.001 s; 1/3 s has no such value and stays."""
    for digits in range(1, 4):
        rounded = float(f"{Ts:.{digits}g}")
        if abs(rounded - Ts) <= AGREE_RTOL * Ts:
            return rounded
    return float(Ts)


def measured_step(t: np.ndarray, where: str, notes: list | None = None) -> float:
    """The sample time (s) of time stamps ``t`` (n,) in s: the median step, rounded to the column's resolution.

    A step of more than 6 significant digits (a computed or measured time vector: 0.0009999839611 s) becomes
    the roundest value within :data:`AGREE_RTOL` (:func:`snap`); ``notes`` then gets a line that says so.
    """
    t = np.asarray(t, dtype=np.float64)
    if len(t) < 2:
        raise DataError(f"{where} has {len(t)} row(s); measuring the sample time needs at least 2 (or give Ts)")
    dt = np.diff(t)
    Ts = float(np.median(dt))
    if not np.all(np.isfinite(dt)) or not Ts > 0 or np.abs(dt - Ts).max() > UNIFORM_RTOL * Ts:
        raise DataError(f"{where} is not uniformly increasing (steps from {np.nanmin(dt):g} to {np.nanmax(dt):g} "
                        "s); resample the record first, or give Ts instead")
    Ts = round_to_resolution(Ts, t)
    if float(f"{Ts:.6g}") == Ts:  # stamps in decimals (0.12341 s): taken as written
        return Ts
    snapped = snap(Ts)
    if snapped != Ts and notes is not None:
        notes.append(f"{where}: its median step {Ts:.10g} s is taken as {snapped:g} s (they agree to "
                     f"{abs(snapped - Ts) / Ts:.1e}, within {AGREE_RTOL:g}); give Ts to force another")
    return snapped


def common_sample_time(per_record: Mapping[str, float], train: list[str], how: str) -> float:
    """One Ts for records whose own sample times agree to :data:`AGREE_RTOL`: the median over ``train``.

    ``per_record`` maps a record's name to its sample time in s; ``how`` says how to force one Ts.
    """
    Ts = float(np.median([per_record[r] for r in train]))
    odd = {r: v for r, v in per_record.items() if abs(v - Ts) > AGREE_RTOL * Ts}
    if odd:
        shown = ", ".join(f"{r}: {v:.10g} s" for r, v in list(per_record.items())[:6])
        raise DataError(f"the records' sample times differ by more than {AGREE_RTOL:g} (relative) from the training "
                        f"records' {Ts:.10g} s ({shown}); {how}, or resample the records to one Ts")
    return Ts


_TIMING = ("Ts", "time_column", "Ts_column", "fs_column")
#: Columns that carry the timing by their name alone, used when no timing is given: the kind each one is.
TIMING_COLUMNS = {"Ts": "Ts_column", "fs": "fs_column", "time": "time_column"}


def _named_timing(reader, files: dict, notes: list) -> dict:
    """The timing of the training files' one column named ``Ts``, ``fs`` or ``time`` (none, or several: {})."""
    first = files["train"][0]
    found = [name for name in TIMING_COLUMNS if name in reader.table(first).columns]
    if len(found) != 1:
        return {}
    kind = TIMING_COLUMNS[found[0]]
    what = {"Ts_column": "the sample time in s", "fs_column": "the sample rate in Hz", "time_column": "time in s"}
    notes.append(f"no sample time given: used the column {found[0]!r} of {first.name} as {what[kind]} (CLI: "
                 "--Ts, --time, --Ts-column or --fs-column choose another)")
    return {kind: found[0]}


def sample_time(reader, files: dict, timing: dict, notes: list) -> float:
    """The files' sample time in s from exactly one of ``timing``'s keys (see :func:`nnfmu.data.load_files`); with
    none, from a column named ``Ts``, ``fs`` or ``time`` (:data:`TIMING_COLUMNS`). ``reader.table(path)`` gives a
    file's :class:`~nnfmu.data.tables.Table`; ``notes`` gets what was assumed."""
    given = [k for k in _TIMING if timing.get(k) is not None]
    if not given:
        timing = _named_timing(reader, files, notes)
        given = list(timing)
    if len(given) != 1:
        raise DataError("give the sample time one way: Ts (in s), a time column (time_column; CLI --time), or a "
                        "column or variable holding Ts in s (Ts_column; CLI --Ts-column) or the rate in Hz "
                        f"(fs_column; CLI --fs-column); got {' and '.join(given) if given else 'none'}")
    (kind,) = given
    if kind == "Ts":
        Ts = float(timing["Ts"])
        if not (np.isfinite(Ts) and Ts > 0):
            raise DataError(f"the sample time Ts (CLI --Ts) must be a positive number of seconds, "
                            f"got {timing['Ts']!r}")
        return Ts
    per_file = {}
    for path in dict.fromkeys(p for group in files.values() for p in group):
        table = reader.table(path)
        if kind == "time_column":
            (col,) = table.resolve(timing[kind])
            per_file[str(path)] = measured_step(table.columns[col], f"{path.name}: the time column {col!r}", notes)
            continue
        value = table.setting(timing[kind])
        if not (np.isfinite(value) and value > 0):
            raise DataError(f"{path}: {timing[kind]!r} holds {value:g}; a sample "
                            f"{'time' if kind == 'Ts_column' else 'rate'} must be positive")
        per_file[str(path)] = value if kind == "Ts_column" else 1.0 / value
    return common_sample_time(per_file, [str(p) for p in files["train"]], "give Ts to force one")
