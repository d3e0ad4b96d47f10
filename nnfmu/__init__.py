"""nnfmu: neural simulation models of dynamical systems, exported as standalone FMUs.

Public API (names are imported on first use, so ``import nnfmu`` stays light):

- data: :class:`Dataset`, :class:`Channel`, :class:`Trajectories`, :func:`load_dataset`,
  :func:`save_dataset`, :func:`from_arrays`, :func:`load_csv`, :func:`load_files` (CSV, .mat, .npz),
  :func:`from_benchmark` (the nonlinear benchmarks' data objects), :func:`load_robot_benchmark`
- scoring: :func:`nrmse`; :func:`evaluate` (co-simulate FMUs in fmpy on a dataset split and score them)
- export: :func:`casadi_model` (a trained network as CasADi ``(init, step)``), :func:`build_fmu`
- the study: :func:`reproduce` (``nnfmu reproduce``), :func:`run_demo` (``nnfmu demo``)
- models and training: :class:`ModelConfig`, :class:`TrainConfig`, :func:`train`, :func:`train_seeds`
  (K seeds: the best or their ensemble), :func:`load_model` (a trained checkpoint; ``model.simulate(u, y0)``)
- linear baseline: :func:`identify_linear`, :class:`LinearModel`, :func:`load_linear`
- physics: :func:`generate_dataset`, :func:`valve_system`, :func:`arm_system`, :func:`slider_system`;
  :func:`sx_to_torch`
- the model contract: :class:`CasadiModel`, :class:`SystemSpec`, :class:`Variable`,
  :class:`ContinuousDynamics` (the ODE of a continuous-time model)
- errors: :mod:`nnfmu.errors` (:class:`NnfmuError` and its subclasses)
"""

from __future__ import annotations

from nnfmu._lazy import lazy_exports

__version__ = "0.1.0"

_LAZY = {
    "Dataset": "nnfmu.data",
    "Channel": "nnfmu.data",
    "Trajectories": "nnfmu.data",
    "load_dataset": "nnfmu.data",
    "save_dataset": "nnfmu.data",
    "from_arrays": "nnfmu.data",
    "load_csv": "nnfmu.data",
    "load_files": "nnfmu.data",
    "from_benchmark": "nnfmu.data",
    "load_robot_benchmark": "nnfmu.data",
    "nrmse": "nnfmu.metrics",
    "NrmseResult": "nnfmu.metrics",
    "CasadiModel": "nnfmu.system",
    "ContinuousDynamics": "nnfmu.system",
    "SystemSpec": "nnfmu.system",
    "Variable": "nnfmu.system",
    "NnfmuError": "nnfmu.errors",
    "load_model": "nnfmu.models",
    "ModelConfig": "nnfmu.models",
    "train": "nnfmu.training",
    "train_seeds": "nnfmu.training",
    "TrainConfig": "nnfmu.training",
    "generate_dataset": "nnfmu.physics",
    "valve_system": "nnfmu.physics",
    "arm_system": "nnfmu.physics",
    "slider_system": "nnfmu.physics",
    "sx_to_torch": "nnfmu.hybrid",
    "HybridConfig": "nnfmu.hybrid",
    "identify_linear": "nnfmu.linear",
    "LinearModel": "nnfmu.linear",
    "load_linear": "nnfmu.linear",
    "evaluate": "nnfmu.cosim",
    "casadi_model": "nnfmu.export.torch_to_casadi",
    "build_fmu": "nnfmu.export.fmu",
    "reproduce": "nnfmu.study",
    "run_demo": "nnfmu.study",
}

__all__ = sorted(_LAZY)


__getattr__, __dir__ = lazy_exports("nnfmu", globals(), _LAZY)
