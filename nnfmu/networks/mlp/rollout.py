"""The MLP as ``window_rollout.c`` computes it (its record's ``rollout_cell``, :mod:`nnfmu.training.rollout_cells`)."""

from __future__ import annotations

from torch import nn

from nnfmu.training.rollout_cells import DENSE, WINDOW, CompiledCell


def rollout_cell(model) -> CompiledCell:
    """Its ``Linear`` layers' weights and biases in order (the last is the output layer), over ``window`` taps."""
    layers = [m for m in model.net if isinstance(m, nn.Linear)]
    return CompiledCell(WINDOW, DENSE, tuple(t for layer in layers for t in (layer.weight, layer.bias)),
                        taps=model.config.window)
