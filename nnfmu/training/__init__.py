"""The one trainer for both training strategies (parallel and series-parallel).

- :func:`train` -> :class:`TrainResult`; options in :class:`TrainConfig`
- :class:`StopTraining`: raise it from a callback to stop
- free-run evaluation: :func:`free_run`, :func:`free_run_nrmse`
- :func:`train_seeds`: K seeds, then the best on validation or their ensemble (:class:`SeedsResult`)
"""

from typing import TYPE_CHECKING

from nnfmu._lazy import declared_exports

# imported on first use: ``python -m nnfmu.training.seed_worker`` imports this package before its own code can
# catch a Ctrl-C, and torch takes seconds to import
if TYPE_CHECKING:  # each public name, declared once (nnfmu._lazy.declared_exports)
    from nnfmu.training.config import STRATEGIES, TrainConfig
    from nnfmu.training.ensemble import KEEP, SeedsResult, train_seeds
    from nnfmu.training.evaluate import free_run, free_run_nrmse
    from nnfmu.training.session import StopTraining
    from nnfmu.training.trainer import TrainResult, dataset_meta, train

__getattr__, __dir__, __all__ = declared_exports(globals())
