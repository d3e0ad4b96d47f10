"""The TCN as ``window_rollout.c`` computes it (its record's ``rollout_cell``, :mod:`nnfmu.training.rollout_cells`)."""

from __future__ import annotations

from nnfmu.training.rollout_cells import DILATED_CONV, WINDOW, CompiledCell


def rollout_cell(model) -> CompiledCell:
    """Per dilated layer its weight and bias, then the head's, each layer over ``kernel_size`` taps."""
    layers = [*model.convs, model.head]
    return CompiledCell(WINDOW, DILATED_CONV, tuple(t for layer in layers for t in (layer.weight, layer.bias)),
                        taps=model.config.kernel_size)
