"""Hybrid models: a CasADi physics model that torch can differentiate through.

- :func:`sx_to_torch` translates a CasADi SX Function into a :class:`TorchFunction`
  (a ``torch.nn.Module``) evaluating it on batches of tensors, with gradients.
- :data:`SUPPORTED_OPS` names the CasADi operation codes it translates.
"""

from nnfmu.hybrid._sx_source import SUPPORTED_OPS
from nnfmu.hybrid.casadi_torch import GRADIENT_MODES, TorchFunction, sx_to_torch

__all__ = ["GRADIENT_MODES", "SUPPORTED_OPS", "TorchFunction", "sx_to_torch"]
