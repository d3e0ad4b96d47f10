"""The dataset container: input/output trajectories of one system, in physical units.

A :class:`Dataset` holds named splits (``train``, ``valid``, ``test``), each a
:class:`Trajectories`: a tuple of input arrays ``u_i`` of shape
``(n_steps_i, n_u)`` and output arrays ``y_i`` of shape ``(n_steps_i, n_y)``.
Trajectories may differ in length; nothing is padded in memory, so no padding
can leak into statistics, training or scores.

Sample ``k`` of a trajectory is taken at ``t_k = t_0 + k * Ts``. The models
predict ``y[k+1]`` from everything up to ``t_k``: ``u[k]`` is the input held
over ``[t_k, t_k + Ts)``.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import Iterable, Mapping, Sequence

import numpy as np

from nnfmu.errors import DataError, ShapeError
from nnfmu.identifiers import is_c_identifier

SPLIT_NAMES = ("train", "valid", "test")
_STD_FLOOR = 1e-12


@dataclass(frozen=True)
class Channel:
    """One input or output signal: ``name`` (a C and FMI identifier) and ``unit``."""

    name: str
    unit: str = ""
    description: str = ""

    def __post_init__(self) -> None:
        if not is_c_identifier(self.name):
            raise DataError(
                f"channel name {self.name!r} is not an identifier; use ASCII letters, digits and "
                "underscores, starting with a letter (it becomes an FMU variable name)"
            )

    def to_json(self) -> dict:
        out = {"name": self.name, "unit": self.unit}
        if self.description:
            out["description"] = self.description
        return out


@dataclass(frozen=True)
class NormStats:
    """Per-channel mean and standard deviation (ddof 0) of a split, in physical units.

    Each array has shape ``(n_u,)`` or ``(n_y,)``. Standard deviations are
    floored at 1e-12 times the larger of 1 and ``|mean|`` so that a constant
    channel normalises to zero instead of dividing by zero.
    """

    u_mean: np.ndarray
    u_std: np.ndarray
    y_mean: np.ndarray
    y_std: np.ndarray


@dataclass(frozen=True)
class Trajectories:
    """One split: ``u[i]`` has shape ``(n_steps_i, n_u)``, ``y[i]`` shape ``(n_steps_i, n_y)``."""

    u: tuple[np.ndarray, ...]
    y: tuple[np.ndarray, ...]

    def __post_init__(self) -> None:
        u = tuple(np.asarray(a, dtype=np.float64) for a in self.u)
        y = tuple(np.asarray(a, dtype=np.float64) for a in self.y)
        object.__setattr__(self, "u", u)
        object.__setattr__(self, "y", y)
        for a in u + y:
            a.setflags(write=False)

    @property
    def n_traj(self) -> int:
        return len(self.u)

    @property
    def lengths(self) -> np.ndarray:
        """Number of samples of each trajectory, shape ``(n_traj,)``."""
        return np.array([len(a) for a in self.u], dtype=np.int64)

    @property
    def n_samples(self) -> int:
        return int(self.lengths.sum())

    @property
    def equal_length(self) -> bool:
        return len(set(self.lengths.tolist())) <= 1

    def stacked(self) -> tuple[np.ndarray, np.ndarray]:
        """``(u, y)`` as arrays of shape ``(n_traj, n_steps, n_*)``; needs equal lengths."""
        if not self.equal_length:
            raise ShapeError(
                f"trajectories have lengths {sorted(set(self.lengths.tolist()))}, expected equal "
                "lengths; call .windows(n) to cut them into equal pieces, or iterate over .u and .y"
            )
        return np.stack(self.u), np.stack(self.y)

    def windows(self, length: int, stride: int | None = None) -> "Trajectories":
        """Cut every trajectory into pieces of ``length`` samples, ``stride`` apart.

        Pieces never straddle two trajectories; a tail shorter than ``length``
        is dropped. ``stride`` defaults to ``length`` (no overlap).
        """
        if length < 2:
            raise ShapeError(f"window length must be at least 2 samples, got {length}")
        stride = length if stride is None else stride
        us, ys = [], []
        for u, y in zip(self.u, self.y):
            for start in range(0, len(u) - length + 1, stride):
                us.append(u[start:start + length])
                ys.append(y[start:start + length])
        if not us:
            raise ShapeError(
                f"no trajectory has {length} samples (longest has {self.lengths.max()}); "
                "choose a shorter window"
            )
        return Trajectories(tuple(us), tuple(ys))

    def subset(self, index: Iterable[int]) -> "Trajectories":
        index = list(index)
        return Trajectories(tuple(self.u[i] for i in index), tuple(self.y[i] for i in index))

    def concatenated(self) -> "Trajectories":
        """All trajectories joined end to end into one (as the robot benchmark's test set)."""
        return Trajectories((np.concatenate(self.u),), (np.concatenate(self.y),))


def _blocks(u: np.ndarray, y: np.ndarray, fraction: float, blocks: int) -> tuple[Trajectories, Trajectories]:
    """``(train, valid)`` of one record: ``blocks`` validation blocks of ``fraction / blocks``, one at the end of each
    of ``blocks`` equal segments (``blocks = 1``: the last ``fraction`` of the record)."""
    if isinstance(blocks, bool) or not isinstance(blocks, (int, np.integer)) or blocks < 1:
        raise DataError(f"validation blocks must be a positive integer, got {blocks!r}")
    n = len(u)
    edges = [int(round(i * n / blocks)) for i in range(blocks + 1)]
    parts = {"train": ([], []), "valid": ([], [])}
    for start, end in zip(edges[:-1], edges[1:]):
        cut = end - int(round(fraction * (end - start)))
        if cut - start < 2 or end - cut < 2:
            raise DataError(f"{blocks} validation blocks of {fraction:.0%} leave pieces shorter than 2 samples of "
                            f"a record of {n}; choose fewer blocks")
        for split, (lo, hi) in (("train", (start, cut)), ("valid", (cut, end))):
            parts[split][0].append(u[lo:hi])
            parts[split][1].append(y[lo:hi])
    return Trajectories(*map(tuple, parts["train"])), Trajectories(*map(tuple, parts["valid"]))


def _as_trajectory_list(arr, what: str) -> list[np.ndarray]:
    """Accept a 3-D array ``(n_traj, n_steps, n)``, a 2-D array ``(n_steps, n)`` or a list of 2-D arrays.

    Nested Python lists of numbers count as arrays: ``[[0.1], [0.2], ...]`` is one trajectory of
    shape ``(n_steps, 1)``; a list whose items are numpy arrays is a list of trajectories.
    """
    if not isinstance(arr, np.ndarray) and not np.isscalar(arr) and not any(isinstance(a, np.ndarray) for a in arr):
        try:
            arr = np.asarray(arr, dtype=np.float64)
        except ValueError:  # ragged nested lists: trajectories of different lengths
            pass
    if isinstance(arr, np.ndarray) or np.isscalar(arr):
        arr = np.asarray(arr, dtype=np.float64)
        if arr.ndim == 3:
            return list(arr)
        if arr.ndim == 2:
            return [arr]
        raise ShapeError(
            f"{what} has shape {arr.shape}, expected (n_traj, n_steps, n) or (n_steps, n); "
            "reshape a single signal to (n_steps, 1)"
        )
    out = [np.asarray(a, dtype=np.float64) for a in arr]
    for i, a in enumerate(out):
        if a.ndim != 2:
            raise ShapeError(
                f"{what}[{i}] has shape {a.shape}, expected (n_steps, n); "
                "reshape a single signal to (n_steps, 1)"
            )
    return out


def make_trajectories(u, y, split: str = "data") -> Trajectories:
    """Build a split from arrays or lists of arrays; see :func:`_as_trajectory_list`."""
    us = _as_trajectory_list(u, f"{split} u")
    ys = _as_trajectory_list(y, f"{split} y")
    if len(us) != len(ys):
        raise ShapeError(f"{split}: {len(us)} input trajectories but {len(ys)} output trajectories")
    for i, (a, b) in enumerate(zip(us, ys)):
        if len(a) != len(b):
            raise ShapeError(
                f"{split} trajectory {i}: u has {len(a)} samples but y has {len(b)}; "
                "inputs and outputs must be sampled at the same instants"
            )
    return Trajectories(tuple(us), tuple(ys))


@dataclass(frozen=True)
class Dataset:
    """Input/output data of one system, split into ``train``, optional ``valid``, and ``test``.

    Attributes
    ----------
    Ts : float
        Sample time in seconds.
    inputs, outputs : tuple of Channel
        Names and units of the ``n_u`` inputs and ``n_y`` outputs.
    splits : mapping of split name to :class:`Trajectories`
    source : dict
        How the data were made or where they came from (JSON-serialisable).
    init_window : int or None
        Samples at the start of every test trajectory that a benchmark gives the model to
        initialise its state before scoring starts (``state_initialization_window_length`` of
        the nonlinear benchmarks); None when the data prescribe none.
    """

    Ts: float
    inputs: tuple[Channel, ...]
    outputs: tuple[Channel, ...]
    splits: Mapping[str, Trajectories]
    source: Mapping = field(default_factory=dict)
    init_window: int | None = None

    def __post_init__(self) -> None:
        object.__setattr__(self, "inputs", tuple(_as_channel(c) for c in self.inputs))
        object.__setattr__(self, "outputs", tuple(_as_channel(c) for c in self.outputs))
        order = {name: i for i, name in enumerate(SPLIT_NAMES)}
        splits = sorted(dict(self.splits).items(), key=lambda kv: order.get(kv[0], len(order)))
        object.__setattr__(self, "splits", dict(splits))
        object.__setattr__(self, "source", dict(self.source))
        if self.init_window is not None:
            if isinstance(self.init_window, bool) or not isinstance(self.init_window, (int, np.integer)) \
                    or self.init_window < 0:
                raise DataError(f"init_window must be a number of samples >= 0 or None, got {self.init_window!r}")
            object.__setattr__(self, "init_window", int(self.init_window))
        validate(self)

    @property
    def n_u(self) -> int:
        return len(self.inputs)

    @property
    def n_y(self) -> int:
        return len(self.outputs)

    @property
    def input_names(self) -> list[str]:
        return [c.name for c in self.inputs]

    @property
    def output_names(self) -> list[str]:
        return [c.name for c in self.outputs]

    def split(self, name: str) -> Trajectories:
        """The split called ``name``; a clear :class:`DataError` if it is missing."""
        if name not in self.splits:
            raise DataError(
                f"dataset has no {name!r} split (it has {', '.join(self.splits) or 'none'}); "
                f"add a {name}.npz, or choose one of the existing splits"
            )
        return self.splits[name]

    @property
    def train(self) -> Trajectories:
        return self.split("train")

    @property
    def test(self) -> Trajectories:
        return self.split("test")

    @property
    def valid(self) -> Trajectories | None:
        return self.splits.get("valid")

    @property
    def consecutive_pieces(self) -> bool:
        """Whether the records are consecutive pieces of one recording that training joins end to end: the
        dataset says so (``source["contiguous"]``, as the robot benchmark's 605-sample pieces), it has a valid split
        of its own (pieces carved out for validation would leave gaps at the seams), and its training split has
        several records. The one rule of the networks' windows (:func:`nnfmu.training.plan.plan_training`) and the
        linear identification (:func:`nnfmu.linear.identify_linear`)."""
        return bool(self.source.get("contiguous")) and self.valid is not None and self.train.n_traj > 1

    def replace(self, **changes) -> "Dataset":
        return dataclasses.replace(self, **changes)

    def with_validation(self, fraction: float | None = 0.1, seed: int = 0, *, n_traj: int | None = None,
                        blocks: int = 1) -> "Dataset":
        """Return a copy whose ``valid`` split is carved out of ``train``.

        With several training trajectories, ``n_traj`` of them, or else ``fraction`` of them (at
        least one, at most all but one), are chosen at random with ``seed``. A single training
        trajectory is cut in time instead: its last ``fraction`` becomes the validation record, or
        with ``blocks = K > 1``, ``K`` blocks of ``fraction / K`` each, spread over the record (the
        record is cut into ``K`` equal segments and each segment's last part is a validation block;
        the training split is the ``K`` pieces before them). An existing ``valid`` split is kept unchanged.
        """
        if self.valid is not None:
            return self
        train = self.train
        if n_traj is not None and train.n_traj == 1:
            raise DataError("the training split is one record: give a validation fraction (its last part "
                            "becomes the validation record), not a number of trajectories")
        if n_traj is not None:
            if isinstance(n_traj, bool) or not isinstance(n_traj, int) or not 1 <= n_traj < train.n_traj:
                raise DataError(f"cannot move {n_traj!r} of the {train.n_traj} training trajectories to validation; "
                                f"give a number from 1 to {train.n_traj - 1}, or a fraction")
        elif fraction is None or not 0.0 < fraction < 1.0:
            raise DataError(f"validation fraction must be in (0, 1), got {fraction}")
        splits = dict(self.splits)
        if train.n_traj >= 2:
            rng = np.random.default_rng(seed)
            n_valid = n_traj or min(train.n_traj - 1, max(1, int(round(fraction * train.n_traj))))
            order = rng.permutation(train.n_traj)
            splits["valid"] = train.subset(sorted(order[:n_valid]))
            splits["train"] = train.subset(sorted(order[n_valid:]))
        else:
            splits["train"], splits["valid"] = _blocks(train.u[0], train.y[0], fraction, blocks)
        return self.replace(splits=splits)

    def with_units(self, units: Mapping[str, str] | Sequence[str] | None) -> "Dataset":
        """Return a copy whose channels carry ``units``: channel name -> unit, or one unit per channel
        (inputs first). Channels not named keep their unit; a name that is no channel raises."""
        names = self.input_names + self.output_names
        if not units:
            return self
        if not isinstance(units, Mapping):
            units = list(units)
            if len(units) != len(names):
                raise DataError(f"got {len(units)} units for {len(names)} channels {names}; give one per channel "
                                "(inputs first) or map them by name (name=unit)")
            units = dict(zip(names, units))
        unknown = sorted(set(units) - set(names))
        if unknown:
            raise DataError(f"units given for {unknown}, which are not channels; the channels are {names}")
        relabel = [Channel(c.name, str(units.get(c.name, c.unit)), c.description) for c in self.inputs + self.outputs]
        return self.replace(inputs=tuple(relabel[:self.n_u]), outputs=tuple(relabel[self.n_u:]))

    def with_measurement_noise(self, fraction: float, seed: int = 0) -> "Dataset":
        """Return a copy with white Gaussian noise added to every output of every split.

        The noise on output ``j`` has standard deviation ``fraction * std_j``, where
        ``std_j`` is output j's standard deviation over the training split; inputs are
        left exact. Use it to make simulated data look measured: noise-free outputs
        flatter series-parallel training, which feeds the measured outputs back.
        The amount is recorded in ``source["measurement_noise"]``.

        Parameters
        ----------
        fraction : float
            Noise standard deviation as a fraction of each output's training std, in [0, 1).
        seed : int
            Seeds the noise, so the same call gives the same data.
        """
        if not 0.0 <= fraction < 1.0:
            raise DataError(f"measurement noise must be a fraction of the output std in [0, 1), got {fraction!r}")
        std = fraction * self.norm_stats("train").y_std
        rng = np.random.default_rng([seed, 2025])
        splits = {name: Trajectories(tr.u, tuple(y + std * rng.standard_normal(y.shape) for y in tr.y))
                  for name, tr in self.splits.items()}
        noise = {"kind": "white Gaussian", "fraction_of_train_std": fraction, "std": std.tolist(), "seed": seed}
        return self.replace(splits=splits, source={**self.source, "measurement_noise": noise})

    def norm_stats(self, split: str = "train") -> NormStats:
        """Mean and std (ddof 0) of every channel over all samples of ``split``."""
        tr = self.split(split)
        u = np.concatenate(tr.u)
        y = np.concatenate(tr.y)
        return NormStats(u.mean(0), _std(u), y.mean(0), _std(y))

    def meta(self) -> dict:
        """The JSON-serialisable description written to ``meta.json``."""
        return {
            "format": "nnfmu-dataset",
            "version": 1,
            "Ts": self.Ts,
            "inputs": [c.to_json() for c in self.inputs],
            "outputs": [c.to_json() for c in self.outputs],
            "source": self.source,
            **({} if self.init_window is None else {"init_window": self.init_window}),
            "splits": {
                name: {"n_traj": tr.n_traj, "lengths": tr.lengths.tolist()}
                for name, tr in self.splits.items()
            },
        }

    def summary(self) -> str:
        """A few human-readable lines: sample time, channels with ranges, split sizes."""
        lines = [f"Ts = {self.Ts:g} s"]
        if self.init_window is not None:
            lines.append(f"init window: the first {self.init_window} samples of a test trajectory initialise the "
                         "model's state before scoring")
        ref = self.splits.get("train") or next(iter(self.splits.values()))
        u_all, y_all = np.concatenate(ref.u), np.concatenate(ref.y)
        for kind, chans, data in (("input ", self.inputs, u_all), ("output", self.outputs, y_all)):
            for j, c in enumerate(chans):
                lines.append(
                    f"{kind} {c.name:<10s} [{c.unit}]  range {data[:, j].min():.4g} .. {data[:, j].max():.4g}"
                )
        for name, tr in self.splits.items():
            lens = sorted(set(tr.lengths.tolist()))
            len_txt = f"{lens[0]}" if len(lens) == 1 else f"{lens[0]}..{lens[-1]}"
            lines.append(f"split {name:<5s}: {tr.n_traj} trajectories x {len_txt} steps ({tr.n_samples} samples)")
        return "\n".join(lines)


def _std(a: np.ndarray) -> np.ndarray:
    std = a.std(0)
    floor = _STD_FLOOR * np.maximum(1.0, np.abs(a.mean(0)))
    return np.maximum(std, floor)


def _as_channel(c) -> Channel:
    if isinstance(c, Channel):
        return c
    if isinstance(c, str):
        return Channel(c)
    if isinstance(c, Mapping):
        return Channel(str(c["name"]), str(c.get("unit", "")), str(c.get("description", "")))
    raise DataError(f"expected a channel name, a Channel or a dict with 'name' and 'unit', got {c!r}")


def validate(ds: Dataset, where: str = "") -> None:
    """Check sample time, names, split names, shapes and finiteness; raise a clear error.

    ``where`` (a path) prefixes the messages so that a user knows which file to fix.
    """
    pre = f"{where}: " if where else ""
    if not (np.isfinite(ds.Ts) and ds.Ts > 0):
        raise DataError(f"{pre}sample time Ts must be a positive number of seconds, got {ds.Ts!r}")
    names = [c.name for c in ds.inputs + ds.outputs]
    dup = sorted({n for n in names if names.count(n) > 1})
    if dup:
        raise DataError(f"{pre}channel names must be unique across inputs and outputs; repeated: {dup}")
    if not ds.inputs or not ds.outputs:
        raise DataError(f"{pre}a dataset needs at least one input and one output channel")
    for name, tr in ds.splits.items():
        if name not in SPLIT_NAMES:
            raise DataError(f"{pre}unknown split {name!r}; splits are {', '.join(SPLIT_NAMES)}")
        if not isinstance(tr, Trajectories):
            raise DataError(f"{pre}split {name!r} must be Trajectories, got {type(tr).__name__}")
        _check_split(tr, name, ds.n_u, ds.n_y, pre)


def _check_split(tr: Trajectories, name: str, n_u: int, n_y: int, pre: str) -> None:
    if tr.n_traj == 0:
        raise DataError(f"{pre}split {name!r} has no trajectories")
    for i, (u, y) in enumerate(zip(tr.u, tr.y)):
        for arr, var, n in ((u, "u", n_u), (y, "y", n_y)):
            if arr.ndim != 2 or arr.shape[1] != n:
                raise ShapeError(
                    f"{pre}{name} trajectory {i}: array {var!r} has shape {arr.shape}, "
                    f"expected (n_steps, {n}) to match the {n} named {'inputs' if var == 'u' else 'outputs'}"
                )
            if len(arr) < 2:
                raise ShapeError(f"{pre}{name} trajectory {i}: needs at least 2 samples, got {len(arr)}")
            bad = ~np.isfinite(arr)
            if bad.any():
                k, j = np.argwhere(bad)[0]
                raise DataError(
                    f"{pre}{name} trajectory {i}: array {var!r} has {int(bad.sum())} non-finite value(s) "
                    f"(first at step {k}, channel {j}, 0-based: {arr[k, j]}); remove or interpolate them before use"
                )
        if len(u) != len(y):
            raise ShapeError(f"{pre}{name} trajectory {i}: u has {len(u)} samples but y has {len(y)}")


def from_arrays(
    *,
    Ts: float,
    u_train,
    y_train,
    u_test,
    y_test,
    u_valid=None,
    y_valid=None,
    input_names: Sequence = (),
    output_names: Sequence = (),
    source: Mapping | None = None,
) -> Dataset:
    """Build a dataset from numpy arrays in physical units.

    Each ``u_*``/``y_*`` is an array of shape ``(n_traj, n_steps, n)``, one
    trajectory of shape ``(n_steps, n)``, or a list of such 2-D arrays (for
    unequal lengths). Names default to ``u1, u2, ...`` and ``y1, y2, ...``;
    pass :class:`Channel` objects (or ``{"name", "unit"}`` dicts) to add units.
    """
    splits = {"train": make_trajectories(u_train, y_train, "train"),
              "test": make_trajectories(u_test, y_test, "test")}
    if (u_valid is None) != (y_valid is None):
        raise DataError("give both u_valid and y_valid, or neither")
    if u_valid is not None:
        splits["valid"] = make_trajectories(u_valid, y_valid, "valid")
    n_u = splits["train"].u[0].shape[1]
    n_y = splits["train"].y[0].shape[1]
    inputs = list(input_names) or [f"u{j + 1}" for j in range(n_u)]
    outputs = list(output_names) or [f"y{j + 1}" for j in range(n_y)]
    return Dataset(Ts=float(Ts), inputs=tuple(inputs), outputs=tuple(outputs), splits=splits,
                   source=dict(source or {"kind": "arrays"}))
