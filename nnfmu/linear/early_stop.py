"""Early stop of the output-error refinement on a validation score (:func:`nnfmu.linear.refine.refine`).

A lower training cost is not a better model: on short or noisy records the free-run fit goes on
lowering the training cost while the validation error rises. The refinement hands every evaluated
system to a :class:`_Monitor`, which keeps the one of lowest training cost, scores it every
``every`` evaluations and raises :class:`_Stopped` after ``patience`` checks in a row without a
better score; the refinement then returns the best-scoring system seen (the start included).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np

from nnfmu.errors import ConfigError
from nnfmu.linear.statespace import StateSpace


@dataclass(frozen=True)
class EarlyStop:
    """Stop the refinement when the validation score stops improving (module docstring).

    Attributes
    ----------
    score : callable ``score(system) -> float``
        Validation error of a normalised :class:`StateSpace` (lower is better), e.g. its free-run NRMSE.
    every : int
        Evaluations between two checks.
    patience : int
        Checks in a row without a better score after which the refinement stops.
    """

    score: Callable[[StateSpace], float]
    every: int = 10
    patience: int = 10

    def __post_init__(self) -> None:
        for name in ("every", "patience"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 1:
                raise ConfigError(f"EarlyStop.{name} must be a positive integer, got {value!r}")


class _Stopped(Exception):
    """Raised inside the minimiser's cost function when validation has stopped improving."""


class _Monitor:
    """Keeps the system of lowest training cost, scores it every ``every`` evaluations, keeps the best score."""

    def __init__(self, rule: EarlyStop, start: StateSpace, cost0: float):
        self.rule, self.candidate, self.scored = rule, None, True
        self.best = (float(rule.score(start)), start, cost0, 0)  # (score, system, cost, evaluation)
        self.score0, self.train_best, self.stale, self.last = self.best[0], cost0, 0, None

    def seen(self, evaluation: int, cost: float, sys: StateSpace | None) -> None:
        if sys is not None and cost < self.train_best:
            self.train_best, self.candidate, self.scored = cost, (sys, cost, evaluation), False
        if evaluation % self.rule.every == 0:
            self.check()
            if self.stale >= self.rule.patience:
                raise _Stopped

    def check(self) -> None:
        """Score the candidate (if new): a better score resets the patience, otherwise it runs down."""
        if self.candidate is not None and not self.scored:
            self.scored = True
            score = float(self.rule.score(self.candidate[0]))
            self.last = (score, self.candidate[1])
            if score < self.best[0]:
                self.best, self.stale = (score, *self.candidate), 0
                return
        self.stale += 1
