"""Hybrid models: a CasADi physics model plus a neural correction, trained in torch and exported as one FMU.

- :class:`HybridConfig` (``arch="hybrid"``) and :class:`HybridStepModel`: physics ODE (valve or
  arm, parameters possibly wrong) + an MLP correcting the state derivative inside the RK4 step
  (or the discrete step); physical parameters optionally trained. Built, trained, saved and
  loaded like any network (``build_model``, ``train``, ``load_model``).
- :func:`hybrid_to_casadi`, :func:`hybrid_casadi_model`: the export (also reached through
  :func:`nnfmu.export.to_casadi` and ``python -m nnfmu.export``).
- The physics in torch, written once in CasADi: :func:`casadi_to_torch` picks
  :func:`compiled_to_torch` (compiled C forward and reverse mode; fast) or :func:`sx_to_torch`
  (a :class:`TorchFunction` translating the SX instructions into torch operations).
- :func:`load_physics_params`: read a JSON parameter file; :data:`PHYSICS`: the physics models.
"""

from nnfmu.hybrid._sx_source import SUPPORTED_OPS
from nnfmu.hybrid.casadi_torch import GRADIENT_MODES, TorchFunction, sx_to_torch
from nnfmu.hybrid.compiled_torch import BACKENDS, CompiledFunction, casadi_to_torch, compiled_to_torch
from nnfmu.hybrid.config import CORRECTIONS, HYBRID_ARCH, PHYSICS, HybridConfig, load_physics_params, physics_system
from nnfmu.hybrid.export import hybrid_casadi_model, hybrid_to_casadi
from nnfmu.hybrid.model import HybridStepModel
from nnfmu.export.exporters import register_exporter
from nnfmu.models.architectures import register_architecture

# models/ and export/ stay below hybrid/: the hybrid architecture registers itself and its exporter (and is
# found through the "nnfmu.architectures" entry point when a stored config names it before anything imported
# this package).
register_architecture(HYBRID_ARCH, config_class=HybridConfig, model_class=HybridStepModel)
register_exporter(HybridStepModel, to_casadi=hybrid_to_casadi, casadi_model=hybrid_casadi_model)

__all__ = [
    "BACKENDS",
    "CORRECTIONS",
    "GRADIENT_MODES",
    "HYBRID_ARCH",
    "PHYSICS",
    "SUPPORTED_OPS",
    "CompiledFunction",
    "HybridConfig",
    "HybridStepModel",
    "TorchFunction",
    "casadi_to_torch",
    "compiled_to_torch",
    "hybrid_casadi_model",
    "hybrid_to_casadi",
    "load_physics_params",
    "physics_system",
    "sx_to_torch",
]
