"""The paper's study as a resumable pipeline: ``nnfmu reproduce``, ``nnfmu tune`` and ``nnfmu demo``.

- :func:`reproduce` -> :class:`StudyResult`: data, 5 architectures x 2 strategies, the linear and
  physics baselines, every model as an FMU scored in fmpy, ``results.md``/``results.json``/figures
- :func:`run_demo`: the README's main job, a small preset of the same pipeline
- budgets: :data:`BUDGETS`, :func:`get_budget`, :class:`Budget`, :class:`Hyper`
- hyperparameter search on Ray Tune (optional extra ``tune``): :func:`tune_architecture`,
  :class:`TuneSettings`, :class:`TuneResult`
"""

from nnfmu.study.budgets import BUDGETS, SYSTEMS, VALVE_NOISE, Budget, Hyper, get_budget
from nnfmu.study.cells import Cell, CellLog, run_cells
from nnfmu.study.demo import DEMO_OUT, run_demo
from nnfmu.study.pipeline import Study, StudyResult, network_name, reproduce
from nnfmu.study.tune import MissingExtraError, TuneResult, TuneSettings, require_ray, tune_architecture

__all__ = [
    "BUDGETS",
    "DEMO_OUT",
    "SYSTEMS",
    "VALVE_NOISE",
    "Budget",
    "Cell",
    "CellLog",
    "Hyper",
    "MissingExtraError",
    "Study",
    "StudyResult",
    "TuneResult",
    "TuneSettings",
    "get_budget",
    "network_name",
    "reproduce",
    "require_ray",
    "run_cells",
    "run_demo",
    "tune_architecture",
]
