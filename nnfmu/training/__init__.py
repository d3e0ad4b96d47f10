"""The one trainer for both training strategies (parallel and series-parallel).

- :func:`train` (alias :func:`fit`) -> :class:`TrainResult`; options in :class:`TrainConfig`
- :class:`StopTraining`: raise it from a callback to stop
- free-run evaluation: :func:`free_run`, :func:`free_run_nrmse`
- :func:`train_seeds`: K seeds, then the best on validation or their ensemble (:class:`SeedsResult`)
"""

from typing import TYPE_CHECKING

from nnfmu._lazy import lazy_exports

# imported on first use: ``python -m nnfmu.training.seed_worker`` imports this package before its own code can
# catch a Ctrl-C, and torch takes seconds to import
_LAZY = {"STRATEGIES": "nnfmu.training.config", "TrainConfig": "nnfmu.training.config",
         "KEEP": "nnfmu.training.ensemble", "SeedsResult": "nnfmu.training.ensemble",
         "train_seeds": "nnfmu.training.ensemble", "free_run": "nnfmu.training.evaluate",
         "free_run_nrmse": "nnfmu.training.evaluate", "StopTraining": "nnfmu.training.session",
         "TrainResult": "nnfmu.training.trainer", "dataset_meta": "nnfmu.training.trainer",
         "fit": "nnfmu.training.trainer", "train": "nnfmu.training.trainer"}

if TYPE_CHECKING:  # what _LAZY imports on first use
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

__getattr__, __dir__ = lazy_exports("nnfmu.training", globals(), _LAZY)
