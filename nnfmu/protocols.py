"""Evaluation protocols: which samples a model may see, where its runs start, and which samples are scored.

Three protocols, combinable (:class:`Protocol`):

- **free run from y0** (the default, the headline of every table): one run per trajectory from the
  measured ``y[0]`` and the inputs; every sample is scored (the first is ``y0`` itself).
- **init window N** (``init_window=N > 1``, as the nonlinear system-identification benchmarks'
  ``state_initialization_window_length``): the model may see the first ``N`` measured samples (a
  model with an init window gets ``y[0 .. N-2]``, ``u[0 .. N-2]`` as its past and starts from
  ``y[N-1]``; any other model starts from ``y[N-1]`` alone) and is scored on samples ``N ..``.
- **H-step-ahead** (``horizon=H``): the run restarts from the measured output every ``H``
  samples (with its measured past window, if it has an init window), so every sample is predicted
  from a measurement at most ``H`` samples old. Scored on the same samples as without it.

Each run is a call ``simulate(u, y0, y_past, u_past) -> (len(u), n_y)`` (first row ``y0``), so
the same protocol serves FMUs in fmpy (:mod:`nnfmu.cosim`) and torch models.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Sequence

import numpy as np

from nnfmu.errors import ConfigError, DataError
from nnfmu.metrics import NrmseResult, nrmse

Simulate = Callable[[np.ndarray, np.ndarray, "np.ndarray | None", "np.ndarray | None"], np.ndarray]


@dataclass(frozen=True, kw_only=True)
class Protocol:
    """How a model is run and scored on a trajectory; see the module docstring.

    Attributes
    ----------
    init_window : int
        ``N >= 1``: samples ``0 .. N-1`` may be seen, samples ``N ..`` are scored (1: the free run from y0).
    horizon : int or None
        ``H >= 1``: restart from the measured output every ``H`` samples; None: one free run.
    """

    init_window: int = 1
    horizon: int | None = None

    def __post_init__(self) -> None:
        if isinstance(self.init_window, bool) or not isinstance(self.init_window, (int, np.integer)) \
                or self.init_window < 1:
            raise ConfigError(f"init_window must be a number of samples >= 1, got {self.init_window!r}")
        object.__setattr__(self, "init_window", int(self.init_window))
        if self.horizon is not None and (isinstance(self.horizon, bool) or not isinstance(self.horizon, int)
                                         or self.horizon < 1):
            raise ConfigError(f"horizon must be None (free run) or a number of samples >= 1, got {self.horizon!r}")

    @property
    def first_scored(self) -> int:
        """Index of the first scored sample: 0 for the plain free run (``y0`` counts), else ``init_window``."""
        return 0 if self.init_window == 1 else self.init_window

    def describe(self) -> str:
        """One line for tables and reports."""
        run = "free run" if self.horizon is None else f"{self.horizon}-step-ahead (restarted from the measured " \
                                                        f"output every {self.horizon} samples)"
        if self.init_window == 1:
            return f"{run} from the measured y0, scored on every sample"
        return (f"{run} after an init window of {self.init_window} samples (samples 0..{self.init_window - 1} "
                f"seen, scored from sample {self.init_window})")

    def to_json(self) -> dict:
        return {"init_window": self.init_window, "horizon": self.horizon, "first_scored": self.first_scored,
                "description": self.describe()}

    def starts(self, n: int) -> list[int]:
        """Start samples of the runs over a trajectory of ``n`` samples (each run ends at the next start)."""
        first = self.init_window - 1
        if n < self.init_window + 1:
            raise DataError(f"a trajectory of {n} samples leaves nothing to score after an init window of "
                            f"{self.init_window} samples; use a shorter --init-window")
        step = self.horizon or n
        return list(range(first, n - 1, step))

    def predict(self, simulate: Simulate, u: np.ndarray, y: np.ndarray, n_past: int) -> np.ndarray:
        """Predictions of samples ``first_scored ..`` of one trajectory ``u`` (n, n_u), ``y`` (n, n_y).

        ``n_past``: how many past samples the model takes (its init window - 1; 0 for none).
        """
        n = len(u)
        starts = self.starts(n)
        pieces = [y[:1]] if self.first_scored == 0 else []
        for k, end in zip(starts, starts[1:] + [n - 1]):
            past = (None, None)
            if n_past:
                lo = k - n_past
                if lo < 0:  # a restart too early for the model's window: the rest state before sample 0
                    pad = lambda a: np.vstack([np.repeat(a[:1], -lo, axis=0), a[:k]])  # noqa: E731
                    past = (pad(y), pad(u))
                else:
                    past = (y[lo:k], u[lo:k])
            pieces.append(simulate(u[k:end + 1], y[k], *past)[1:])
        return np.vstack(pieces)

    def padded(self, prediction: np.ndarray, n: int) -> np.ndarray:
        """A prediction of :meth:`predict` over all ``n`` samples, NaN where nothing is scored (for plots)."""
        return np.vstack([np.full((n - len(prediction), prediction.shape[1]), np.nan), prediction])

    def score(self, measured: Sequence[np.ndarray], predictions: Sequence[np.ndarray]) -> NrmseResult:
        """NRMSE of :meth:`predict`'s outputs against the scored samples of each measured trajectory."""
        return nrmse([y[self.first_scored:] for y in measured], list(predictions))
