"""Co-simulate any FMU with fmpy on a dataset split: the one scoring path of nnfmu.

Every model, whether network, linear baseline, physics or hybrid, is scored
the same way: its FMU is simulated by fmpy over each trajectory of the split
with

- the dataset's inputs as fmpy's input table (sample ``k`` at ``t_k = k * Ts``,
  held by the FMU over the step);
- the start values ``<name>_start`` of every output set to the measured ``y0``;
- the output interval (the communication step) equal to ``Ts``;

and the recorded outputs at ``t_0 .. t_{N-1}`` are handed to
:func:`nnfmu.metrics.nrmse`. The FMU is unpacked and instantiated once and
reset between trajectories. :func:`evaluate` also counts the samples whose
inputs lie outside the FMU's declared valid range (``min``/``max``).
"""

from __future__ import annotations

import os
import shutil
from dataclasses import dataclass, field
from pathlib import Path
from typing import Sequence

import numpy as np

from nnfmu.data import Dataset
from nnfmu.errors import DataError, DataFileError, SimulationError
from nnfmu.metrics import NrmseResult
from nnfmu.protocols import Protocol
from nnfmu.tempdirs import make_temp_dir
from nnfmu.valid_range import OutOfRange, count_outside
from nnfmu.window_names import fmu_init_window, window_start_values

_TS_RTOL = 1e-9
# fmpy's FMI 2 logger proxy keeps a C-global pointer to the most recent logger callback; if that
# callback were freed with its FMU instance, a later log message from any FMU would crash the process.
# The callback structures of our instances are therefore kept alive for the life of the process.
_LIVE_CALLBACKS: list = []


@dataclass(frozen=True)
class FmuInfo:
    """What :func:`inspect_fmu` reads from an FMU's modelDescription.xml."""

    path: Path
    model_name: str
    fmi_version: str
    Ts: float | None
    inputs: tuple[str, ...]
    outputs: tuple[str, ...]
    parameters: tuple[str, ...]
    input_ranges: dict = field(default_factory=dict)  # input name -> (min, max), None where undeclared
    init_window: int = 1  # samples its init sees: 1 + its window parameters per channel (nnfmu.window_names)


def inspect_fmu(path: str | os.PathLike) -> FmuInfo:
    """Read an FMU's interface; :class:`DataFileError` if it is missing or not an FMU."""
    from fmpy import read_model_description

    path = Path(path)
    if not path.exists():
        raise DataFileError(f"FMU {path} not found; build one with `python -m nnfmu.export` or `nnfmu linear`")
    try:
        md = read_model_description(str(path), validate=False)
    except Exception as exc:  # fmpy raises bare Exception and zipfile/XML errors
        raise DataFileError(f"{path} is not a readable FMU ({exc})") from exc
    if md.coSimulation is None:
        raise DataFileError(f"{path} has no co-simulation interface; nnfmu scores co-simulation FMUs")
    exp = md.defaultExperiment
    Ts = float(exp.stepSize) if exp is not None and exp.stepSize is not None else None
    by_causality = {}
    for v in md.modelVariables:
        by_causality.setdefault(v.causality, []).append(v.name)
    ranges = {v.name: tuple(None if b is None else float(b) for b in (v.min, v.max))
              for v in md.modelVariables if v.causality == "input"}
    outputs = tuple(by_causality.get("output", []))
    return FmuInfo(path, md.modelName, md.fmiVersion, Ts, tuple(by_causality.get("input", [])), outputs,
                   tuple(by_causality.get("parameter", [])), ranges, fmu_init_window(md, outputs))


def check_compatible(info: FmuInfo, dataset: Dataset) -> None:
    """Raise :class:`DataError` unless the FMU's inputs, outputs, start parameters and Ts fit the dataset."""
    want_in, want_out = dataset.input_names, dataset.output_names
    if sorted(info.inputs) != sorted(want_in):
        raise DataError(f"{info.path.name}: FMU inputs {list(info.inputs)} do not match the dataset's inputs "
                        f"{want_in}; score it on data of the system it was built for")
    missing = [n for n in want_out if n not in info.outputs]
    if missing:
        raise DataError(f"{info.path.name}: FMU has no output(s) {missing}; its outputs are {list(info.outputs)}")
    no_start = [f"{n}_start" for n in want_out if f"{n}_start" not in info.parameters]
    if no_start:
        raise DataError(f"{info.path.name}: FMU lacks the start parameter(s) {no_start} that set y0; "
                        "it was not built by nnfmu's FMU builder")
    if info.Ts is not None and abs(info.Ts - dataset.Ts) > _TS_RTOL * dataset.Ts:
        raise DataError(f"{info.path.name}: FMU sample time {info.Ts:g} s differs from the dataset's "
                        f"Ts = {dataset.Ts:g} s")


class FmuSimulator:
    """An FMU unpacked and instantiated once, simulated on many trajectories.

    Use as a context manager; ``simulate(u, y0)`` maps ``u`` (N, n_u) and ``y0``
    (n_y,) in physical units to the recorded outputs (N, n_y), first row y0.
    """

    def __init__(self, path: str | os.PathLike, input_names: Sequence[str], output_names: Sequence[str],
                 Ts: float):
        from fmpy import extract, instantiate_fmu, read_model_description

        self.info = inspect_fmu(path)
        self.input_names, self.output_names, self.Ts = list(input_names), list(output_names), float(Ts)
        self.messages: list[str] = []
        self._dir = str(make_temp_dir("nnfmu-cosim-"))  # removed by a later run if this process is killed
        try:
            self._unzipdir = extract(str(path), unzipdir=self._dir)
            self._md = read_model_description(self._unzipdir)
            self._fmu = instantiate_fmu(self._unzipdir, self._md, fmi_type="CoSimulation",
                                        logger=self._log)
            _LIVE_CALLBACKS.append(getattr(self._fmu, "callbacks", None))
        except Exception as exc:
            shutil.rmtree(self._dir, ignore_errors=True)
            raise SimulationError(f"{self.info.path.name}: cannot load the FMU ({exc})") from exc
        self._used = False

    def _log(self, *args) -> None:
        msg = args[-1]
        self.messages.append(msg.decode(errors="replace") if isinstance(msg, bytes) else str(msg))

    def simulate(self, u: np.ndarray, y0: np.ndarray, y_past: np.ndarray | None = None,
                 u_past: np.ndarray | None = None) -> np.ndarray:
        """``y_past`` (N-1, n_y), ``u_past`` (N-1, n_u): the samples before t0, set as the FMU's window
        parameters (an FMU with an init window of N samples; :mod:`nnfmu.window_names`)."""
        from fmpy import simulate_fmu

        u = np.asarray(u, dtype=float)
        n = len(u)
        table = np.zeros(n, dtype=[("time", float)] + [(name, float) for name in self.input_names])
        table["time"] = np.arange(n) * self.Ts
        for j, name in enumerate(self.input_names):
            table[name] = u[:, j]
        start = {f"{name}_start": float(v) for name, v in zip(self.output_names, np.ravel(y0))}
        if y_past is not None:
            start.update(window_start_values(self.info, self.output_names, self.input_names, y_past, u_past))
        if self._used:
            self._fmu.reset()
        self._used = True
        self.messages.clear()
        try:
            res = simulate_fmu(self._unzipdir, start_time=0.0, stop_time=(n - 1) * self.Ts,
                               output_interval=self.Ts, input=table, start_values=start,
                               output=self.output_names, model_description=self._md,
                               fmu_instance=self._fmu, fmi_type="CoSimulation")
        except Exception as exc:
            log = "; ".join(self.messages[-3:])
            raise SimulationError(f"{self.info.path.name}: simulation failed ({exc})"
                                  + (f"; the FMU said: {log}" if log else "")) from exc
        y = np.column_stack([res[name] for name in self.output_names])
        if len(y) != n:
            raise SimulationError(f"{self.info.path.name}: fmpy returned {len(y)} samples, expected {n}")
        return y

    def close(self) -> None:
        try:
            self._fmu.freeInstance()
        finally:
            shutil.rmtree(self._dir, ignore_errors=True)

    def __enter__(self) -> "FmuSimulator":
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def simulate_split(path: str | os.PathLike, dataset: Dataset, split: str = "test",
                   progress: bool = False, protocol: Protocol = Protocol()) -> list[np.ndarray]:
    """Simulate the FMU at ``path`` on every trajectory of ``split`` under ``protocol``.

    One array per trajectory of the samples the protocol scores (the default free run: all
    ``N_i`` samples, the first being y0).
    """
    info = inspect_fmu(path)
    check_compatible(info, dataset)
    trajectories = dataset.split(split)
    out = []
    with FmuSimulator(path, dataset.input_names, dataset.output_names, dataset.Ts) as sim:
        items = zip(trajectories.u, trajectories.y)
        if progress:
            from tqdm import tqdm

            items = tqdm(items, total=trajectories.n_traj, desc=Path(path).name, leave=False)
        for u, y in items:
            out.append(protocol.predict(sim.simulate, u, y, info.init_window - 1))
    return out


@dataclass(frozen=True)
class Evaluation:
    """The score of one FMU on one split, with its predictions (one (N_i, n_y) array per trajectory)."""

    name: str
    path: Path
    result: NrmseResult
    predictions: list[np.ndarray] = field(repr=False)
    out_of_range: OutOfRange | None = None  # test samples outside the FMU's valid input range

    def to_json(self, outputs: Sequence) -> dict:
        """Name, FMU path and the scores of :meth:`NrmseResult.to_json` (``outputs``: names or Channels)."""
        doc = {"name": self.name, "fmu": str(self.path), **self.result.to_json(outputs)}
        if self.out_of_range is not None:
            doc["inputs_out_of_range"] = self.out_of_range.to_json()
        return doc


def evaluate(paths: Sequence[str | os.PathLike], dataset: Dataset, split: str = "test",
             names: Sequence[str] | None = None, progress: bool = False,
             protocol: Protocol = Protocol()) -> list[Evaluation]:
    """Co-simulate every FMU on ``split`` and score it with :func:`nnfmu.metrics.nrmse`.

    ``names`` label the FMUs (default: file stem). All FMUs are checked against
    the dataset before the first one is simulated, so a mismatch fails fast.
    ``protocol``: the free run from y0 (default), after an init window, or H-step-ahead
    (:mod:`nnfmu.protocols`); the predictions cover the samples it scores.
    """
    paths = [Path(p) for p in paths]
    names = list(names) if names is not None else [p.stem for p in paths]
    measured, inputs = dataset.split(split).y, dataset.split(split).u
    infos = [inspect_fmu(p) for p in paths]
    for info in infos:
        check_compatible(info, dataset)
    out = []
    for name, p, info in zip(names, paths, infos):
        pred = simulate_split(p, dataset, split, progress=progress, protocol=protocol)
        outside = count_outside(inputs, dataset.input_names, info.input_ranges)
        out.append(Evaluation(name, p, protocol.score(list(measured), pred), pred, outside))
    return out
