"""The one trainer for both training strategies (parallel and series-parallel).

- :func:`train` (alias :func:`fit`) -> :class:`TrainResult`; options in :class:`TrainConfig`
- :class:`StopTraining`: raise it from a callback to stop
- free-run evaluation: :func:`free_run`, :func:`free_run_nrmse`
- :func:`train_seeds`: K seeds, then the best on validation or their ensemble (:class:`SeedsResult`)
"""

from nnfmu.training.config import STRATEGIES, TrainConfig
from nnfmu.training.ensemble import KEEP, SeedsResult, train_seeds
from nnfmu.training.evaluate import free_run, free_run_nrmse
from nnfmu.training.session import StopTraining
from nnfmu.training.trainer import TrainResult, dataset_meta, fit, train

__all__ = [
    "KEEP",
    "STRATEGIES",
    "SeedsResult",
    "StopTraining",
    "TrainConfig",
    "TrainResult",
    "dataset_meta",
    "fit",
    "free_run",
    "free_run_nrmse",
    "train",
    "train_seeds",
]
