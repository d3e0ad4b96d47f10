"""``TCNConfig``: the temporal convolutional network's config (``arch="tcn"``, :mod:`nnfmu.networks.tcn`)."""

from __future__ import annotations

from dataclasses import dataclass

from nnfmu.errors import ShapeError
from nnfmu.models import ModelConfig


def tcn_receptive_field(layers: int, kernel_size: int) -> int:
    """Number of past samples a TCN with dilations 1, 2, 4, ... sees: ``1 + (k-1)(2^layers - 1)``."""
    return 1 + (kernel_size - 1) * (2 ** layers - 1)


@dataclass(frozen=True, kw_only=True)
class TCNConfig(ModelConfig):
    """:class:`~nnfmu.models.ModelConfig` of ``arch="tcn"``: ``layers`` dilated causal convolutions (default 3,
    dilation ``2**i`` in layer ``i``) of ``hidden`` channels and kernel size ``kernel_size >= 2``; its window is
    its receptive field ``1 + (kernel_size-1)(2**layers - 1)`` (None computes it)."""

    arch: str = "tcn"

    def default_layers(self) -> int:
        return 3

    def resolve_window(self) -> int:
        if self.kernel_size < 2:
            raise ShapeError(f"a TCN needs kernel_size >= 2, got {self.kernel_size}")
        field = tcn_receptive_field(self.layers, self.kernel_size)
        if self.window not in (None, field):
            raise ShapeError(f"a TCN with {self.layers} layers and kernel_size {self.kernel_size} sees "
                             f"{field} samples, got window={self.window}; pass window={field}, leave it out, or "
                             "change layers/kernel_size")
        return field
