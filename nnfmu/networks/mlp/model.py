"""MLP step network over a window of the last ``L`` samples (state layout: :mod:`nnfmu.models.window`; config:
:class:`~nnfmu.networks.mlp.config.MLPConfig`).

::

    N = Linear(H -> n_y) ∘ [act ∘ Linear(. -> H), dropout] x layers  ( [y_{k-L+1}, u_{k-L+1}, ..., y_k, u_k] )
    y_{k+1} = y_k + skip_scale * N   (skip=True),   N   (skip=False)

The input vector is the window flattened sample by sample, oldest first. The
network is one ``nn.Sequential`` of ``nn.Linear``, activation and
``nn.Dropout`` modules, which :func:`nnfmu.export.to_casadi` walks.
"""

from __future__ import annotations

from typing import Mapping

import torch
from torch import nn
from torch.nn import functional as F

from nnfmu.errors import ConfigError
from nnfmu.models.activation import activation_module
from nnfmu.models.window import WindowStepModel
from nnfmu.networks.mlp.config import MLPConfig


class MLPStepModel(WindowStepModel):
    """Multilayer perceptron on the flattened window ``(L * (n_y + n_u),)``."""

    def __init__(self, config: MLPConfig, meta: Mapping | None = None):
        if not isinstance(config, MLPConfig):
            raise ConfigError(f"MLPStepModel needs an MLPConfig, got {type(config).__name__}")
        super().__init__(config, meta)
        modules: list[nn.Module] = []
        n_in = config.window * config.n_in
        for _ in range(config.layers):
            modules += [nn.Linear(n_in, config.hidden), activation_module(config.activation),
                        nn.Dropout(config.dropout)]
            n_in = config.hidden
        modules.append(nn.Linear(n_in, config.n_y))
        self.net = nn.Sequential(*modules)
        self.check_sizes()

    def _net(self, v: torch.Tensor) -> torch.Tensor:
        """``self.net(v)`` without the per-module call overhead where it is safe (the rollout's hot loop)."""
        for module in self.net:
            if type(module) is nn.Linear:
                v = F.linear(v, module.weight, module.bias)
            elif type(module) is nn.Dropout and not (self.training and module.p > 0):
                continue
            else:
                v = module(v)
        return v

    def _predict_windows(self, window: torch.Tensor) -> torch.Tensor:
        return self._net(window.reshape(window.shape[0], -1))

    def _predict_sequence(self, padded: torch.Tensor) -> torch.Tensor:
        L = self.config.window
        # unfold: (B, T, C, L) -> samples oldest first, each sample's channels together
        windows = padded.unfold(1, L, 1).transpose(2, 3)
        return self._net(windows.reshape(*windows.shape[:2], -1))
