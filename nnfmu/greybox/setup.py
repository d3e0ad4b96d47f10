"""What a grey-box fit estimates and where from: the free parameters, their bounds and the starting points.

Kept apart from the fit itself (:mod:`nnfmu.greybox.fit`) so that every check of the user's choices
(an unknown parameter name, bounds that exclude the start, a dataset that is not the model's) runs, and
fails in one line, before any simulation.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from nnfmu.data.sampling import AGREE_RTOL
from nnfmu.errors import ConfigError, DataError
from nnfmu.physics.base import PhysicsSystem

__all__ = ["Unknowns", "choose_unknowns", "check_dataset", "spread_starts"]


@dataclass(frozen=True)
class Unknowns:
    """The free parameters: indices into ``p``, names, start values and bounds (arrays (n_f,), +-inf: none)."""

    index: np.ndarray
    names: tuple[str, ...]
    start: np.ndarray
    lower: np.ndarray
    upper: np.ndarray


def _names(what: str, given, known: list[str]) -> list[str]:
    unknown = [n for n in given if n not in known]
    if unknown:
        raise ConfigError(f"{what} {', '.join(unknown)}: no such parameter; the model's parameters are "
                          f"{', '.join(known)}")
    return list(given)


#: The largest finite bound a fit accepts: the solver squares scaled steps and bounds, and 1e308 overflows.
MAX_BOUND = 1e150


def choose_unknowns(system: PhysicsSystem, *, free=None, fixed=(), bounds=None, start=None) -> Unknowns:
    """The free parameters of ``system`` and their bounds and starts.

    ``free``: names (default ``system.free_parameters``; None there: all); ``fixed``: names taken out of them;
    ``bounds``: ``{name: (lo, hi)}`` (None: unbounded on that side) over each parameter's ``min`` / ``max``;
    ``start``: ``{name: value}`` over each parameter's nominal ``start``. Raises ConfigError naming the fix.
    """
    known = [v.name for v in system.parameters]
    chosen = _names("free parameter", free if free is not None else (system.free_parameters or known), known)
    out = set(_names("fixed parameter", fixed, known))
    chosen = [n for n in chosen if n not in out]
    if not chosen:
        raise ConfigError("no parameter is left free to fit; name some with --free (the model's parameters are "
                          f"{', '.join(known)})")
    bounds, start = dict(bounds or {}), dict(start or {})
    _names("--bounds for", bounds, known)
    _names("--start for", start, known)
    index = np.array([known.index(n) for n in chosen], dtype=int)
    values, lower, upper = [], [], []
    for i in index:
        v = system.parameters[i]
        lo, hi = bounds.get(v.name, (v.min, v.max))
        lo, hi = -np.inf if lo is None else float(lo), np.inf if hi is None else float(hi)
        s = float(start.get(v.name, v.start))
        if not np.isfinite(s):
            raise ConfigError(f"the start of parameter {v.name} is {s}; give a finite value (--start {v.name}=...)")
        if lo > hi:
            raise ConfigError(f"the bounds of {v.name} are [{lo:g}, {hi:g}], lower above upper; swap them")
        if max((abs(b) for b in (lo, hi) if np.isfinite(b)), default=0.0) > MAX_BOUND:
            raise ConfigError(f"the bounds of {v.name} [{lo:g}, {hi:g}] {v.unit} are beyond {MAX_BOUND:g}, where the "
                              f"solver's squares overflow; give bounds within +-{MAX_BOUND:g}, or leave a side empty "
                              f"for no bound (--bounds {v.name}=LO:)")
        if not lo <= s <= hi:
            raise ConfigError(f"the bounds of {v.name} [{lo:g}, {hi:g}] {v.unit} exclude its start {s:g}; widen "
                              f"--bounds {v.name}=LO:HI or give a start inside (--start {v.name}=VALUE)")
        values.append(s), lower.append(lo), upper.append(hi)
    return Unknowns(index=index, names=tuple(chosen), start=np.array(values), lower=np.array(lower),
                    upper=np.array(upper))


def check_dataset(system: PhysicsSystem, dataset) -> None:
    """The dataset must carry the model's inputs and outputs (names and units, in order) and its sample time."""
    for what, model_vars, channels in (("inputs", system.inputs, dataset.inputs),
                                       ("outputs", system.outputs, dataset.outputs)):
        want = [(v.name, v.unit) for v in model_vars]
        got = [(c.name, c.unit) for c in channels]
        if want != got:
            show = lambda pairs: ", ".join(f"{n} [{u}]" for n, u in pairs)  # noqa: E731
            raise DataError(f"the dataset's {what} ({show(got)}) are not the model's ({show(want)}); import the "
                            f"data with the model's names and units (nnfmu import --inputs/--outputs/--units)")
    if not np.isclose(dataset.Ts, system.Ts, rtol=AGREE_RTOL, atol=0.0):  # as records agree with each other
        raise DataError(f"the dataset's sample time is {dataset.Ts:g} s but the model {system.name!r} steps at "
                        f"{system.Ts:g} s; resample the data (nnfmu import --resample) or set the model's Ts")


def spread_starts(unknowns: Unknowns, n: int, rng: np.random.Generator) -> np.ndarray:
    """``n`` starting points (n, n_f): the given start first, then random ones inside the bounds.

    Bounded on both sides: uniform between the bounds (log-uniform where they are positive and span more than
    a factor of 10). Otherwise: the start times a factor log-uniform in [1/3, 3] (a start of 0: uniform in
    [-1, 1]), clipped to the bounds.
    """
    points = [unknowns.start]
    for _ in range(n - 1):
        point = []
        for s, lo, hi in zip(unknowns.start, unknowns.lower, unknowns.upper):
            if np.isfinite(lo) and np.isfinite(hi):
                log = lo > 0 and hi > 10 * lo
                value = np.exp(rng.uniform(np.log(lo), np.log(hi))) if log else rng.uniform(lo, hi)
            else:
                value = s * np.exp(rng.uniform(-np.log(3), np.log(3))) if s != 0 else rng.uniform(-1, 1)
            point.append(float(np.clip(value, lo, hi)))
        points.append(np.array(point))
    return np.array(points)
