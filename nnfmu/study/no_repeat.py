"""A Ray Tune search algorithm that never trains the same grid point twice.

Optuna's TPE (and HyperOpt) sample from the grid's values with replacement, so on a small grid they
propose points already tried: ``nnfmu tune --search optuna`` trained one grid point twice. :class:`NoRepeat`
wraps such a searcher: a point proposed again is not run; the wrapped searcher gets the score it already has
(or a failed trial while the first run of that point is still going), and is asked again. When it keeps
proposing tried points (the grid is exhausted), the search ends.
"""

from __future__ import annotations

import copy

from ray.tune.search import Searcher


def _key(config: dict) -> tuple:
    return tuple(sorted((k, repr(v)) for k, v in config.items()))


class NoRepeat(Searcher):
    """``searcher``, with every proposed configuration run at most once (module docstring).

    ``max_asks``: proposals tried per trial before the search counts as exhausted.
    """

    def __init__(self, searcher: Searcher, max_asks: int = 200):
        super().__init__(metric=searcher.metric, mode=searcher.mode)
        self.searcher, self.max_asks = searcher, max_asks
        self.scores: dict[tuple, float | None] = {}  # point -> its score (None while it runs or if it failed)
        self.runs: dict[str, tuple[str, tuple]] = {}  # Ray's trial id -> (the wrapped searcher's id, point)

    def set_search_properties(self, metric, mode, config, **spec) -> bool:
        done = self.searcher.set_search_properties(metric, mode, config, **spec)
        self._metric, self._mode = self.searcher.metric, self.searcher.mode
        return done

    def suggest(self, trial_id: str):
        for ask in range(self.max_asks):
            inner_id = trial_id if ask == 0 else f"{trial_id}_repeat{ask}"
            config = self.searcher.suggest(inner_id)
            if config is None or config == Searcher.FINISHED:
                return config
            point = _key(config)
            if point not in self.scores:
                self.scores[point] = None
                self.runs[trial_id] = (inner_id, point)
                return config
            known = self.scores[point]  # a repeat: tell the searcher what it already knows, and ask again
            self.searcher.on_trial_complete(inner_id, result=None if known is None else {self.metric: known},
                                            error=known is None)
        return Searcher.FINISHED

    def on_trial_result(self, trial_id: str, result: dict) -> None:
        if trial_id in self.runs:
            self.searcher.on_trial_result(self.runs[trial_id][0], result)

    def on_trial_complete(self, trial_id: str, result: dict | None = None, error: bool = False) -> None:
        if trial_id not in self.runs:
            return
        inner_id, point = self.runs.pop(trial_id)
        if not error and result and self.metric in result:
            self.scores[point] = result[self.metric]
        self.searcher.on_trial_complete(inner_id, result=result, error=error)

    # Ray checkpoints the search with these, as its own wrapper ConcurrencyLimiter does
    def get_state(self) -> dict:
        return copy.deepcopy({"scores": self.scores, "runs": self.runs})

    def set_state(self, state: dict) -> None:
        self.scores, self.runs = state["scores"], state["runs"]

    def save(self, checkpoint_path: str) -> None:
        self.searcher.save(checkpoint_path)

    def restore(self, checkpoint_path: str) -> None:
        self.searcher.restore(checkpoint_path)
