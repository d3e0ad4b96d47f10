"""The valid input range of a model: the ``min``/``max`` an exported FMU declares and guards.

- Networks, hybrids and the linear baseline: the range of each input over the
  training data, widened on each side by :data:`RANGE_MARGIN` of its width
  (an input that never varied in training is valid at that value only). The
  range is stored with the model: in a checkpoint's ``meta["input_range"]``
  and in a linear model's JSON.
- Physics models: their physical limits, set on their input :class:`Variable`.

Inside the FMU an input outside ``[min, max]`` makes ``doStep`` return a
Warning (one log message per excursion) or, with the FMU parameter
``input_range_error = true``, an Error (docs/fmu.md). ``nnfmu evaluate``
counts the test samples outside the range with :func:`count_outside`.

Start values: a trained model's FMU declares neutral ones, the training means (the
model's normalisation buffers ``u_mean`` and ``y_mean``), as each input's start and
each ``<y>_start`` (:func:`stored_input_variables`, :func:`with_starts`); an input's
start is then clipped into its range (docs/fmu.md, "Start values").
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Sequence

import numpy as np

from nnfmu.errors import ShapeError
from nnfmu.system import Variable

#: Fraction of the training range's width added below its minimum and above its maximum.
RANGE_MARGIN = 0.1
#: For checkpoints written before ranges were stored: mean +- this many standard deviations.
LEGACY_STD_SPAN = 4.0

Range = tuple[float, float]


def training_range(u: Sequence[np.ndarray], margin: float = RANGE_MARGIN) -> list[Range]:
    """Per input, ``(lo, hi)`` of ``u`` (trajectories of shape (N_i, n_u)) widened by ``margin`` of the width."""
    stacked = np.concatenate([np.asarray(x, dtype=float).reshape(len(x), -1) for x in u])
    lo, hi = np.nanmin(stacked, axis=0), np.nanmax(stacked, axis=0)
    pad = margin * (hi - lo)
    return [(float(a), float(b)) for a, b in zip(lo - pad, hi + pad)]


def normalisation_range(mean: Sequence[float], std: Sequence[float], span: float = LEGACY_STD_SPAN) -> list[Range]:
    """``mean +- span * std`` per input: the estimate used when a checkpoint stores no range."""
    return [(float(m - span * s), float(m + span * s)) for m, s in zip(mean, std)]


def with_ranges(variables: Sequence[Variable], ranges: Sequence[Range] | None) -> tuple[Variable, ...]:
    """``variables`` with ``min``/``max`` from ``ranges`` and ``start`` moved into the range if outside it."""
    if ranges is None:
        return tuple(variables)
    out = []
    for v, (lo, hi) in zip(variables, ranges, strict=True):
        out.append(dataclasses.replace(v, min=float(lo), max=float(hi), start=float(np.clip(v.start, lo, hi))))
    return tuple(out)


def with_starts(variables: Sequence[Variable], starts) -> tuple[Variable, ...]:
    """``variables`` with ``start`` from ``starts`` (one finite value per variable, e.g. a model's
    ``y_mean`` buffer, shape (n,)); None leaves them unchanged."""
    if starts is None:
        return tuple(variables)
    values = [float(s) for s in np.asarray(_numbers(starts), dtype=float).ravel()]
    if len(values) != len(variables) or not all(np.isfinite(values)):
        raise ShapeError(f"expected {len(variables)} finite start values, got {values}; pass one per variable")
    return tuple(dataclasses.replace(v, start=s) for v, s in zip(variables, values))


def _numbers(values):
    """A torch tensor (any device) or array-like as something numpy reads."""
    return values.detach().cpu().numpy() if hasattr(values, "detach") else values


def stored_input_variables(meta: dict, u_mean=None, u_std=None) -> tuple[Variable, ...]:
    """A trained model's input Variables (from its ``meta``) with their valid range and start value.

    The range is ``meta["input_range"]``, stored at training time; a model saved before
    ranges were stored gets :func:`normalisation_range` of ``u_mean`` and ``u_std``. The start
    value is ``u_mean`` (shape (n_u,), the training mean, physical units) clipped into the range.
    """
    variables = with_starts([Variable(**{k: ch[k] for k in ("name", "unit", "description") if k in ch})
                             for ch in meta["inputs"]], u_mean)
    ranges = meta.get("input_range")
    if ranges is None and u_mean is not None:
        ranges = normalisation_range(np.asarray(_numbers(u_mean), dtype=float),
                                     np.asarray(_numbers(u_std), dtype=float))
    return with_ranges(variables, ranges)


@dataclass(frozen=True)
class OutOfRange:
    """How many samples of a data split lie outside an FMU's valid input range.

    ``samples`` counts samples with at least one input outside; ``per_input`` counts per input name.
    """

    samples: int
    total: int
    per_input: dict

    def to_json(self) -> dict:
        return {"samples": self.samples, "total": self.total, "per_input": dict(self.per_input)}

    def describe(self) -> str:
        if not self.samples:
            return f"0 of {self.total} samples"
        worst = ", ".join(f"{name} {n}" for name, n in self.per_input.items() if n)
        return f"{self.samples} of {self.total} samples ({worst})"


def count_outside(u: Sequence[np.ndarray], names: Sequence[str], ranges: dict) -> OutOfRange:
    """Count samples of ``u`` (trajectories (N_i, n_u), columns named ``names``) outside ``ranges``.

    ``ranges`` maps an input name to ``(min, max)``, either bound None for unbounded; inputs without
    an entry are never outside.
    """
    stacked = np.concatenate([np.asarray(x, dtype=float).reshape(len(x), -1) for x in u])
    outside = np.zeros(stacked.shape, dtype=bool)
    for j, name in enumerate(names):
        lo, hi = ranges.get(name, (None, None))
        if lo is not None:
            outside[:, j] |= stacked[:, j] < lo
        if hi is not None:
            outside[:, j] |= stacked[:, j] > hi
    return OutOfRange(int(outside.any(axis=1).sum()), len(stacked),
                      {name: int(outside[:, j].sum()) for j, name in enumerate(names)})
