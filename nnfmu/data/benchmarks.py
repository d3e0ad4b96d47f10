"""The nonlinear system-identification benchmarks' data objects as a dataset (:func:`from_benchmark`).

The ``nonlinear-benchmarks`` package (extra ``benchmarks``) downloads and cuts
the benchmarks of nonlinearbenchmark.org (Cascaded Tanks, Silverbox,
Wiener-Hammerstein, EMPS, CED, ParWH, F16) into ``Input_output_data`` objects:
``u``, ``y`` (shape (N,) or (N, n)), ``sampling_time`` in s, ``name`` and
``state_initialization_window_length``, the samples at the start of a test
record that a model may use to set its state before the error counts. nnfmu
keeps that number as the dataset's ``init_window`` (``meta.json``).
"""

from __future__ import annotations

import contextlib
from pathlib import Path
from typing import Sequence

import numpy as np

from nnfmu.data.dataset import Dataset, from_arrays
from nnfmu.data.sampling import common_sample_time
from nnfmu.errors import DataError, DataFileError


def _records(data, split: str) -> list:
    items = list(data) if isinstance(data, (list, tuple)) else [data]
    for i, item in enumerate(items):
        if not all(hasattr(item, a) for a in ("u", "y", "sampling_time")):
            raise DataError(f"{split} item {i} is a {type(item).__name__}, expected a nonlinear_benchmarks "
                            "Input_output_data (with u, y and sampling_time)")
    if not items:
        raise DataError(f"no {split} data given")
    return items


def _column(a, where: str) -> np.ndarray:
    a = np.asarray(a, dtype=np.float64)
    if a.ndim == 1:
        return a[:, None]
    if a.ndim != 2:
        raise DataError(f"{where} has shape {a.shape}, expected (N,) or (N, n)")
    return a


def _sample_time(splits: dict, Ts: float | None) -> float:
    """``Ts`` if given, else the training records' ``sampling_time`` (all records must agree to 1e-4, relative)."""
    if Ts is not None:
        if not (np.isfinite(Ts) and Ts > 0):
            raise DataError(f"Ts (CLI --Ts) must be a positive number of seconds, got {Ts!r}")
        return float(Ts)
    times = {f"{s} record {i}": float(r.sampling_time) for s, recs in splits.items() for i, r in enumerate(recs)
             if r.sampling_time is not None}
    if not times:
        raise DataError("the data are discrete-time (no sampling_time); give Ts in s")
    train = [k for k in times if k.startswith("train ")] or list(times)
    return common_sample_time(times, train, "give Ts (CLI: --Ts) to force one")


def _init_window(records: list) -> int | None:
    """The largest ``state_initialization_window_length`` of the test records (None if none gives one)."""
    given = [int(r.state_initialization_window_length) for r in records
             if getattr(r, "state_initialization_window_length", None) is not None]
    return max(given) if given else None


def from_benchmark(
    train,
    test=None,
    *,
    valid=None,
    inputs: Sequence = (),
    outputs: Sequence = (),
    Ts: float | None = None,
    name: str | None = None,
) -> Dataset:
    """Build a dataset from ``nonlinear_benchmarks.Input_output_data`` objects.

    Parameters
    ----------
    train : Input_output_data, or a list of them; or, with ``test`` omitted, the ``(train, test)``
        pair a benchmark function returns: ``from_benchmark(nonlinear_benchmarks.Cascaded_Tanks())``.
    test, valid : Input_output_data or a list of them (each record is one trajectory).
    inputs, outputs : channel names, :class:`Channel` objects or ``{"name", "unit"}`` dicts
        (default ``u1, u2, ...`` and ``y1, y2, ...``, also for a single channel: Silverbox gives
        ``u1`` and ``y1``; CLI: ``nnfmu import nonlinear-benchmark NAME --inputs u --outputs y``).
    Ts : sample time in s; default the training records' ``sampling_time``. Records whose
        sampling times differ by more than 1e-4 (relative) are refused unless ``Ts`` is given.
    name : the benchmark's name, recorded in ``source``.

    Returns
    -------
    Dataset
        Its ``init_window`` is the test records' largest ``state_initialization_window_length``
        (None if they give none).
    """
    if test is None:
        if not (isinstance(train, (tuple, list)) and len(train) == 2):
            raise DataError("no test data: pass test=..., or the (train, test) pair that a nonlinear_benchmarks "
                            "function returns, e.g. from_benchmark(nonlinear_benchmarks.Cascaded_Tanks())")
        train, test = train
    splits = {"train": _records(train, "train"), "test": _records(test, "test")}
    if valid is not None:
        splits["valid"] = _records(valid, "valid")
    arrays = {s: ([_column(r.u, f"{s} record {i} u") for i, r in enumerate(recs)],
                  [_column(r.y, f"{s} record {i} y") for i, r in enumerate(recs)]) for s, recs in splits.items()}
    source = {"kind": "nonlinear-benchmark", "benchmark": name, "name": name or "benchmark",
              "records": {s: [str(getattr(r, "name", "") or "") for r in recs] for s, recs in splits.items()}}
    ds = from_arrays(Ts=_sample_time(splits, Ts),
                     u_train=arrays["train"][0], y_train=arrays["train"][1],
                     u_test=arrays["test"][0], y_test=arrays["test"][1],
                     u_valid=arrays.get("valid", (None, None))[0], y_valid=arrays.get("valid", (None, None))[1],
                     input_names=inputs, output_names=outputs, source=source)
    return ds.replace(init_window=_init_window(splits["test"]))


BENCHMARKS = ("Cascaded_Tanks", "CED", "EMPS", "Silverbox", "WienerHammerBenchMark", "ParWH", "F16")


def fetch_benchmark(name: str, *, data_dir: str | None = None, **options) -> Dataset:
    """Call ``nonlinear_benchmarks.<name>()`` (it downloads the data once into its cache) and convert the result.

    ``options`` go to :func:`from_benchmark` (``inputs``, ``outputs``, ``Ts``).
    """
    try:
        import nonlinear_benchmarks
    except ImportError as exc:
        raise DataError("the nonlinear benchmarks need the package nonlinear-benchmarks: "
                        "pip install 'nnfmu[benchmarks]'") from exc
    if name not in BENCHMARKS:
        raise DataError(f"unknown benchmark {name!r}; choose one of {', '.join(BENCHMARKS)} (the ones split into "
                        "training and test data by the nonlinear_benchmarks package)")
    load = getattr(nonlinear_benchmarks, name)
    try:
        with _extracted_files_used(load, data_dir):
            result = load(dir_placement=data_dir)
    except Exception as exc:  # the package raises bare exceptions for download and file errors
        raise DataFileError(f"nonlinear_benchmarks.{name}() failed: {type(exc).__name__}: {exc}; it downloads the "
                            "data on first use, so it needs the network once (or its files in --data-dir)") from exc
    return from_benchmark(result, name=name, **options)


@contextlib.contextmanager
def _extracted_files_used(load, data_dir: str | None):
    """While ``load`` runs: a benchmark folder in ``data_dir`` that holds the extracted files counts as present.

    The package looks for its downloaded archive (``<data_dir>/<Name>/<Name>Files.zip``) and downloads again when
    only the files extracted from it are there (someone copied the folder, or deleted the archive to save space).
    """
    fetch = load.__globals__.get("cashed_download")
    if data_dir is None or fetch is None:
        yield
        return

    def cached(url, name_dir, *args, dir_placement=None, **kwargs):
        folder = Path(dir_placement if dir_placement is not None else data_dir) / name_dir
        if folder.is_dir() and any(p.suffix.lower() in (".mat", ".csv") for p in folder.rglob("*")):
            return str(folder)
        return fetch(url, name_dir, *args, dir_placement=dir_placement, **kwargs)

    load.__globals__["cashed_download"] = cached  # the name the package's loaders look up when they run
    try:
        yield
    finally:
        load.__globals__["cashed_download"] = fetch
