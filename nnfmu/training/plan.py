"""Training choices made from the data when the user leaves them out: windows, batch, budget, validation.

The TrainConfig defaults (whole trajectories, batch 64, 100 epochs, patience 15) suit many short
trajectories (the valve). On one long record they give one optimiser step per epoch, so early stopping
ends the run after a few dozen steps (issue 21: the two-tank system stopped at best epoch 1-9, worse
than the mean). :func:`plan_training` chooses instead, from the number and length of the records and
the linear model's slowest time scale:

- ``join``: records that the dataset says are consecutive pieces of one recording
  (``source["contiguous"]``, as the robot benchmark's 605-sample pieces) are joined end to end, so that
  the windows below may be as long as the free runs the model must survive, not cut at the pieces' seams
  (only with a valid split of the dataset's own: pieces carved out for validation would leave gaps);
- ``truncate``: whole trajectories when the longest is at most two windows long, else windows of
  ``clamp(5 tau, MIN_WINDOW, MAX_WINDOW)`` samples (``tau`` the slowest time constant in samples, so
  that an error of the initial state estimated at a window's start decays to under 1 % within it;
  an integrator or a pole at ``|z| >= 0.9999`` counts as :data:`MAX_WINDOW`);
- ``batch_size``: a quarter of the windows (or trajectories) of an epoch, 1 .. 64, so that an epoch
  makes at least about four optimiser steps;
- the budget in optimiser steps: ``epochs`` and ``patience`` are :data:`BUDGET_STEPS` and
  :data:`PATIENCE_STEPS` divided by the steps of an epoch, within :data:`DEFAULT_MINUTES` of wall time
  (a GRU-32 on 10 x 400 samples makes thousands of steps a minute, a wide or deep network, a long record or a
  network in torch far fewer: the time is the budget that binds for slow networks); with
  ``max_minutes`` alone the time is the budget;
- ``valid_fraction`` (one record without a valid split): a tail long enough to rank models over a
  horizon like the test's, ``min(test length, 25 %)`` of the record and at least 10 %, plus the init
  window's samples, which are seen and not scored.

Every option the user gave is kept as given. The returned lines say what was chosen and why.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from nnfmu.data import Dataset

MIN_WINDOW = 200
MAX_WINDOW = 2000
BUDGET_STEPS = 20000
PATIENCE_STEPS = 4000
DEFAULT_MINUTES = 10.0
MAX_BATCH = 64


@dataclass(frozen=True)
class Plan:
    """The chosen TrainConfig fields (``changes``) and one line per choice (``lines``)."""

    changes: dict = field(default_factory=dict)
    lines: list = field(default_factory=list)


def slowest_time_constant(linear) -> float:
    """The slowest time constant of a linear model in samples, ``-1 / ln |z|`` of its largest pole (inf at |z| ~ 1)."""
    if linear is None or linear.n_x == 0:
        return math.nan
    radius = float(np.max(np.abs(np.linalg.eigvals(linear.system.A))))
    return math.inf if radius >= 0.9999 else -1.0 / math.log(max(radius, 1e-12))


def _window(tau: float) -> int:
    if math.isnan(tau):
        return 4 * MIN_WINDOW
    return MAX_WINDOW if math.isinf(tau) else int(min(max(5.0 * tau, MIN_WINDOW), MAX_WINDOW))


def valid_fraction(ds: Dataset, init_window: int = 1) -> float | None:
    """The validation tail for one record without a valid split (module docstring), or None if not applicable."""
    if ds.valid is not None or ds.train.n_traj != 1:
        return None
    n = int(ds.train.lengths[0])
    test = int(ds.test.lengths.max()) if "test" in ds.splits else n
    tail = max(0.10 * n, min(test, 0.25 * n)) + (init_window - 1)
    return float(min(max(tail / n, 0.05), 0.5))


def validation_line(ds: Dataset, frac: float, blocks: int = 1) -> str:
    """What the plan says of the validation it carves from the one training record (its tail, or ``blocks``)."""
    samples = int(frac * ds.train.lengths[0])
    if blocks > 1:
        return (f"validation: {frac:.0%} of the record ({samples} samples) in {blocks} blocks spread over it "
                "(--valid-blocks 1: its tail)")
    return f"validation: the last {frac:.0%} of the record ({samples} samples, long enough to rank models over a " \
           "test-like horizon)"


def plan_training(ds: Dataset, given: dict, *, linear=None, init_window: int = 1) -> Plan:
    """The data-driven choices for the TrainConfig fields not in ``given`` (field -> value the user gave)."""
    changes, lines = {}, []
    if "valid_fraction" not in given and (frac := valid_fraction(ds, init_window)) is not None:
        changes["valid_fraction"] = frac
        lines.append(validation_line(ds, frac))
    lengths = np.asarray(ds.train.lengths, dtype=float) * (1.0 - changes.get("valid_fraction", 0.0))
    whole = "truncate" in given and given["truncate"] is None  # whole trajectories asked for (a hybrid's plan)
    # joined only with a valid split of its own: validation pieces carved at random would leave gaps at the seams
    if "join" not in given and not whole and ds.consecutive_pieces:  # the linear identification joins them too
        changes["join"] = True
        lines.append(f"records: the {len(lengths)} training records joined end to end (the dataset says they are "
                     "consecutive pieces of one recording; --no-join keeps them apart)")
    if given.get("join", changes.get("join")):
        lengths = np.array([lengths.sum()])
    truncate = given.get("truncate")
    if "truncate" not in given:
        tau = slowest_time_constant(linear)
        window = _window(tau)
        if lengths.max() > 2 * window:
            changes["truncate"] = truncate = window
            why = ("an integrating or very slow mode" if math.isinf(tau) else
                   "no linear model" if math.isnan(tau) else f"the slowest time constant {tau:.0f} samples")
            lines.append(f"windows: --truncate {window} ({why}; the longest record has {int(lengths.max())} samples)")
        else:
            lines.append(f"windows: whole trajectories (the longest, {int(lengths.max())} samples, is short)")
    pieces = max(float(np.sum(np.floor(lengths / truncate))) if truncate else float(len(lengths)), 1.0)
    batch = given.get("batch_size")
    if batch is None:
        batch = changes["batch_size"] = int(min(max(pieces // 4, 1), MAX_BATCH))
        lines.append(f"batch: {batch} of {int(pieces)} {'windows' if truncate else 'trajectories'} an epoch")
    steps = max(1, math.ceil(pieces / batch))
    if "max_minutes" in given and not {"epochs", "patience"} & set(given):
        lines.append(f"budget: the time given, {steps} optimiser steps an epoch")
        return Plan(changes, lines)
    if "epochs" not in given:
        changes["epochs"] = max(1, math.ceil(BUDGET_STEPS / steps))
        if "max_minutes" not in given:
            changes["max_minutes"] = DEFAULT_MINUTES
    if "patience" not in given:
        changes["patience"] = max(1, math.ceil(PATIENCE_STEPS / steps))
    epochs, patience = changes.get("epochs", given.get("epochs")), changes.get("patience", given.get("patience"))
    cap = changes.get("max_minutes", given.get("max_minutes"))
    lines.append(f"budget: {epochs} epochs of {steps} optimiser steps" + (f", at most {cap:g} minutes" if cap else "")
                 + f", stopping after {patience} epochs without a better validation free run")
    return Plan(changes, lines)


def still_improving(history: list, best_epoch: int, stop_reason: str) -> bool:
    """Whether a run ended by its budget while validation was still improving (best epoch in its last tenth)."""
    if stop_reason not in ("epochs", "time-budget") or not history:
        return False
    last = history[-1]["epoch"]
    return best_epoch > 0 and best_epoch >= last - max(1, last // 10)
