"""Greedy ensemble selection on validation: which trained networks to average, and whether to average at all.

Forward selection (Caruana et al., "Ensemble selection from libraries of models", ICML 2004), without
replacement: start from the best network on validation alone; in each round, try each remaining
candidate as one more member of the ensemble (:class:`~nnfmu.models.EnsembleStepModel`: the mean output
fed back, as the FMU runs it) and add the one whose ensemble has the lowest validation free-run NRMSE,
if that is at least :data:`MIN_GAIN` (relative) below the current one. It stops at :data:`MAX_MEMBERS`,
when no candidate gains enough, or at ``deadline``. Each member must pay for itself: an FMU of K members
costs K times one network's step.

The candidates are ranked by the caller (best on validation first), and should exclude networks that
never improved on their start (they pull the mean back towards it). Every number here is a validation
score; the test split is not seen.

Where validation ranks the networks loosely, the greedy choice buys validation more than unseen data, and the
plain average of every candidate can do better there. :func:`cross_check` asks which, on validation alone: each
rule is chosen on one half of the validation and scored on the other (two-fold cross-validation of the choice
itself). Measured as a rule for the seeds (``benchmarks/seed_count.py``), it did not beat the greedy selection on
data it had not seen, so nothing chooses by it (docs/accuracy.md).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Sequence

import torch

from nnfmu.data import Trajectories
from nnfmu.models import EnsembleStepModel, StepModel
from nnfmu.training.evaluate import free_run_nrmse

MAX_MEMBERS = 4
MIN_GAIN = 0.01  # relative fall of the validation NRMSE that one more member must bring


@dataclass(frozen=True)
class Selection:
    """The kept model and how it was chosen.

    ``chosen``: indices into the candidates, in the order added (``chosen[0] == 0``); ``scores``: the
    validation free-run NRMSE after each addition (``scores[0]``: the best candidate alone), so
    ``scores[-1]`` is ``model``'s; ``stopped``: why the selection ended; ``rejected``: the validation
    NRMSE of the best ensemble tried last and not kept (None if none was).
    """

    model: StepModel
    chosen: list = field(default_factory=list)
    scores: list = field(default_factory=list)
    stopped: str = ""
    rejected: float | None = None


def ensemble_score(models: Sequence[StepModel], valid: Trajectories, context: int = 1) -> tuple[StepModel, float]:
    """``(model, its free-run NRMSE on valid)``: ``models[0]``, or the ensemble of ``models`` (inf: diverged)."""
    model = models[0] if len(models) == 1 else EnsembleStepModel.from_members(list(models)).eval()
    with torch.no_grad():
        result = free_run_nrmse(model, valid, context=context)
    return model, float("inf") if result is None else float(result.mean)


def _score(models: Sequence[StepModel], valid: Trajectories, context: int) -> float:
    return ensemble_score(models, valid, context)[1]


def validation_halves(valid: Trajectories, context: int = 1) -> tuple[Trajectories, Trajectories] | None:
    """Two halves of ``valid``: its records alternately (0, 2, ... and 1, 3, ...) where it has two or more, else its
    one record cut at the middle sample. None where one record is too short to cut (each half needs more than
    ``context`` samples, the init window plus one scored sample)."""
    if valid.n_traj >= 2:
        return (Trajectories(valid.u[0::2], valid.y[0::2]), Trajectories(valid.u[1::2], valid.y[1::2]))
    n = int(valid.lengths[0])
    if n // 2 <= context:
        return None
    mid = n // 2
    return (Trajectories((valid.u[0][:mid],), (valid.y[0][:mid],)),
            Trajectories((valid.u[0][mid:],), (valid.y[0][mid:],)))


@dataclass(frozen=True)
class CrossCheck:
    """The greedy selection and the average of every candidate, each chosen on one half of the validation and
    scored there on the other: ``select`` and ``average`` are the means over the two halves of those free-run
    NRMSE (dimensionless); ``members``: how many networks the selection kept on each half."""

    select: float
    average: float
    members: tuple

    @property
    def averages(self) -> bool:
        """True where the average scored lower than the selection on the halves it was not chosen on."""
        return self.average < self.select


def cross_check(candidates: Sequence[StepModel], valid: Trajectories, *, context: int = 1,
                min_gain: float = MIN_GAIN) -> CrossCheck | None:
    """Does the greedy selection on ``valid`` carry beyond the data that chose it, better than averaging all?

    For each half of :func:`validation_halves`, the candidates are ranked on that half and selected greedily
    (:func:`select_ensemble`, every candidate may join), and the kept model is scored on the other half; the
    average of all ``candidates`` is scored on both (it involves no choice). None with fewer than two candidates
    or a validation too short to halve.
    """
    halves = validation_halves(valid, context)
    if len(candidates) < 2 or halves is None:
        return None
    candidates = [m.eval() for m in candidates]
    average = EnsembleStepModel.from_members(list(candidates)).eval()
    select, mean, members = [], [], []
    for chosen_on, scored_on in (halves, halves[::-1]):
        own = [_score([m], chosen_on, context) for m in candidates]
        ranked = [candidates[i] for i in sorted(range(len(candidates)), key=own.__getitem__)]
        picked = select_ensemble(ranked, chosen_on, context=context, max_members=len(ranked), min_gain=min_gain)
        select.append(_score([picked.model], scored_on, context))
        mean.append(_score([average], scored_on, context))
        members.append(len(picked.chosen))
    return CrossCheck(float(sum(select) / 2), float(sum(mean) / 2), tuple(members))


def select_ensemble(candidates: Sequence[StepModel], valid: Trajectories, *, context: int = 1,
                    deadline: float | None = None, after: float = 0.0, max_members: int = MAX_MEMBERS,
                    min_gain: float = MIN_GAIN) -> Selection:
    """The greedy ensemble of ``candidates`` (best on validation first) on the ``valid`` free runs.

    ``context``: as in :func:`~nnfmu.training.evaluate.free_run_nrmse` (the models' ``init_window``).
    ``deadline``: a :func:`time.monotonic` time by which the selection and the caller's work with the kept model
    (scoring the test: ``after`` validation free runs of each of its members) are done. An ensemble of K members
    is taken to cost K times the first candidate's validation free run; one that would not end in time is not
    scored, and the best so far is kept. One candidate, or ``max_members`` 1, keeps ``candidates[0]``.
    """
    candidates = [m.eval() for m in candidates]
    started = time.monotonic()
    chosen, scores = [0], [_score(candidates[:1], valid, context)]
    one = time.monotonic() - started  # seconds of one member's validation free run
    rejected = None

    def in_time(k: int) -> bool:
        return deadline is None or time.monotonic() + k * one * (1.0 + after) <= deadline

    while True:
        if len(chosen) == len(candidates):
            stopped = "every candidate is in"
            break
        if len(chosen) >= max_members:
            stopped = f"{max_members} members"
            break
        tried, late = {}, False
        for i in (i for i in range(len(candidates)) if i not in chosen):
            if not in_time(len(chosen) + 1):
                late = True
                break
            tried[i] = _score([candidates[j] for j in chosen + [i]], valid, context)
        best = min(tried, key=tried.get, default=None)
        if best is not None and tried[best] <= scores[-1] * (1.0 - min_gain):
            chosen.append(best)
            scores.append(tried[best])
            if not late:
                continue
        further = "further " if len(chosen) > 1 else ""
        gain = f"no {further}member lowered the validation NRMSE by {100 * min_gain:g} %"
        stopped = "the time was up" if late else gain
        rejected = None if best is None or best in chosen else tried[best]
        break
    model = candidates[0] if len(chosen) == 1 else EnsembleStepModel.from_members([candidates[i] for i in chosen])
    return Selection(model.eval(), chosen, scores, stopped, rejected)
