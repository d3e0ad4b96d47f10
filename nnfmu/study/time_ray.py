"""Ray Tune pieces of the time search (:mod:`nnfmu.study.time_search`); imported only once Ray is known to be there.

- :class:`Asha`: Ray Tune's ASHA scheduler, remembering which trials it stopped (for the table);
- :class:`Points`: a searcher handing out the planned points in order, and none once the time left is short;
- :class:`Echo`: one printed line per finished trial.
"""

from __future__ import annotations

import time

from ray.tune import Callback
from ray.tune.schedulers import ASHAScheduler
from ray.tune.search import Searcher

from nnfmu.study.time_space import label
from nnfmu.study.tune import METRIC


class Asha(ASHAScheduler):
    """ASHA (asynchronous successive halving) that records the point index of every trial it stops, and the last
    result of every trial (``last``: point index -> result dict)."""

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.stopped_points: set = set()
        self.last: dict = {}

    def on_trial_result(self, tune_controller, trial, result):
        self.last[int(trial.config["trial"])] = dict(result)
        decision = super().on_trial_result(tune_controller, trial, result)
        if decision == self.STOP:
            self.stopped_points.add(int(trial.config["trial"]))
        return decision


class Points(Searcher):
    """Trials 0 .. n-1 in order (config ``{"trial": i}``); FINISHED once ``min_left_s`` or less is left before ``end``.

    ``end`` is a :func:`time.monotonic` time of this (the driver's) process.
    """

    def __init__(self, n: int, end: float, min_left_s: float):
        super().__init__()
        self.n, self.end, self.min_left_s, self.next = n, end, min_left_s, 0

    def suggest(self, trial_id: str):
        if self.next >= self.n or self.end - time.monotonic() < self.min_left_s:
            return Searcher.FINISHED
        self.next += 1
        return {"trial": self.next - 1}

    def on_trial_complete(self, trial_id: str, result=None, error: bool = False) -> None:
        pass

    def save(self, checkpoint_path: str) -> None:  # nothing to resume: a search is not continued
        pass

    def restore(self, checkpoint_path: str) -> None:
        pass


class Echo(Callback):
    """Print ``search: trial i <point>: validation NRMSE x after e epochs[, stopped by ASHA]`` as trials end."""

    def __init__(self, points: list, scheduler: Asha):
        self.points, self.scheduler = points, scheduler

    def on_trial_complete(self, iteration, trials, trial, **info):
        i = int(trial.config["trial"])
        result = trial.last_result or {}
        score = result.get(METRIC)
        text = "no epoch finished" if score is None else (f"best validation NRMSE {score:.4f} after "
                                                          f"{int(result.get('epoch', 0))} epochs")
        stopped = ", stopped by ASHA" if i in self.scheduler.stopped_points else ""
        print(f"search: trial {i} {label(self.points[i])}: {text}{stopped}", flush=True)

    def on_trial_error(self, iteration, trials, trial, **info):
        i = int(trial.config["trial"])
        print(f"search: trial {i} {label(self.points[i])} failed in Ray", flush=True)
