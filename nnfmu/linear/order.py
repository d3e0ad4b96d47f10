"""The order of the linear baseline, chosen on refined candidates (step 3 of :mod:`nnfmu.linear.identify`).

Every order the singular values support is realised from one subspace fit and scored by its
free-run NRMSE on the check split (validation, else training). Those *subspace* scores are not
enough to rank orders: where the subspace model is biased (measured data in closed loop,
integrating plants, records cut out of a longer one, not at rest) every order's free run can be
worse than the mean, and the least bad one is then the smallest. On the robot all twenty scored
1.00 to 2.14, order 1 won, and after refinement it scored 0.978 on validation where order 12
reached 0.787. The refinement is what makes those models good, so the orders are compared after it:

1. candidates: the order of the best subspace score (the smallest within ``tolerance`` of it),
   and the ``count - 1`` orders with the largest singular-value gaps ``s[n-1] / s[n]`` (where
   the data show a change in the number of states);
2. each candidate is refined shortly (a tenth of the refinement's evaluations, early-stopped on the
   same check split) and scored again;
3. the order chosen is the smallest candidate whose refined score is within ``tolerance`` of the
   best; the caller goes on refining it from its short refinement's result, with the evaluations
   left, so the model kept is never worse on the check split than that result.

With ``count=1``, without refinement, or without a validation split (:mod:`nnfmu.linear.identify`
passes no ``refine`` then), the subspace scores alone decide (the rule before).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from nnfmu.errors import DataError
from nnfmu.linear.statespace import StateSpace
from nnfmu.progress import tqdm

_SUPPORTED = 1e-10  # a singular value below this fraction of the largest shows no state


@dataclass(frozen=True)
class OrderChoice:
    """The order chosen, the subspace score of every order tried and the refined score of each candidate.

    ``subspace`` and ``refined`` map orders to free-run NRMSEs (mean over outputs and trajectories) on
    the check split; ``refined`` is empty when the subspace scores alone decided. ``start`` is the
    chosen candidate's shortly refined system (None: none was refined) and ``evaluations`` the
    evaluations that refinement used.
    """

    order: int
    subspace: dict[int, float]
    refined: dict[int, float] = field(default_factory=dict)
    start: StateSpace | None = None
    evaluations: int = 0


def smallest_within(scores: dict[int, float], tolerance: float) -> int:
    """The smallest order whose score is within ``tolerance`` (relative, at least 1e-6 absolute) of the best."""
    best = min(scores.values())
    limit = best + max(tolerance * best, 1e-6)
    return min(n for n, v in scores.items() if v <= limit)


def gap_orders(singular_values: np.ndarray, max_order: int, count: int) -> list[int]:
    """The ``count`` orders ``n <= max_order`` with the largest ratios ``s[n-1] / s[n]``, largest first.

    A singular value below ``1e-10`` of the largest ends the list of supported orders: the order
    just before it has an infinite gap.
    """
    sv = np.asarray(singular_values, dtype=float)
    floor = _SUPPORTED * sv[0]
    gaps = {}
    for n in range(1, min(max_order, len(sv)) + 1):
        if sv[n - 1] <= floor:
            break
        gaps[n] = np.inf if n == len(sv) or sv[n] <= floor else sv[n - 1] / sv[n]
    return sorted(gaps, key=lambda n: (-gaps[n], n))[:max(count, 0)]


def choose_order(singular_values: np.ndarray, max_order: int, *, model: Callable[[int], StateSpace],
                 score: Callable[[StateSpace], float], tolerance: float, count: int,
                 refine: Callable[[StateSpace], tuple[StateSpace, int]] | None,
                 progress: bool = False) -> OrderChoice:
    """Choose the order (module docstring).

    Parameters
    ----------
    singular_values : ndarray, shape (s * n_y,)
        Of the subspace fit, largest first.
    max_order : int
        Largest order tried.
    model : callable ``model(n) -> StateSpace``
        The (stabilised) subspace model of order ``n``, normalised coordinates.
    score : callable ``score(system) -> float``
        Free-run NRMSE of a system on the check split.
    tolerance : float
        Relative tolerance of both comparisons (subspace scores, refined scores).
    count : int
        Most candidates refined: the subspace choice and up to ``count - 1`` gap orders.
    refine : callable ``refine(system) -> (system, evaluations)`` or None
        The short refinement; None: the subspace scores decide.
    progress : bool
        Progress bars over the orders tried and the candidates refined.
    """
    sv = np.asarray(singular_values, dtype=float)
    subspace = {}
    orders = tqdm(range(1, min(max_order, len(sv)) + 1), disable=not progress, unit="order",
                  desc="linear: choose the order", dynamic_ncols=True)
    for n in orders:
        if sv[n - 1] <= _SUPPORTED * sv[0]:
            break  # the data show no more states
        subspace[n] = score(model(n))
        orders.set_postfix(order=n, nrmse=f"{subspace[n]:.4f}", best=min(subspace, key=subspace.get))
    orders.close()
    if not subspace:  # every singular value is zero: constant data
        raise DataError("the training data show no dynamics (the inputs and outputs are constant, so every "
                        "singular value is 0); a linear model needs data that vary: check the dataset's signals")
    first = smallest_within(subspace, tolerance)
    candidates = [first] + [n for n in gap_orders(sv, max_order, count) if n != first][:max(count - 1, 0)]
    if refine is None or len(candidates) < 2:
        return OrderChoice(first, subspace)
    refined, results = {}, {}
    bar = tqdm(sorted(candidates), disable=not progress, unit="order", dynamic_ncols=True,
               desc=f"linear: compare orders {', '.join(map(str, sorted(candidates)))} refined")
    for n in bar:
        results[n] = refine(model(n))
        refined[n] = score(results[n][0])
        bar.set_postfix(order=n, nrmse=f"{refined[n]:.4f}", best=min(refined, key=refined.get))
    bar.close()
    order = smallest_within(refined, tolerance)
    return OrderChoice(order, subspace, refined, *results[order])
