"""``MLPConfig``: the multilayer perceptron's config (``arch="mlp"``, :mod:`nnfmu.networks.mlp`)."""

from __future__ import annotations

from dataclasses import dataclass

from nnfmu.models import ModelConfig

#: The window ``L`` when left out: the MLP sees the last 4 samples of ``[y, u]``.
DEFAULT_WINDOW = 4


@dataclass(frozen=True, kw_only=True)
class MLPConfig(ModelConfig):
    """:class:`~nnfmu.models.ModelConfig` of ``arch="mlp"``: ``layers`` hidden layers (default 2) of ``hidden``
    units on the flattened window of the last ``window`` samples (free, default 4)."""

    arch: str = "mlp"

    def default_layers(self) -> int:
        return 2

    def resolve_window(self) -> int:
        return DEFAULT_WINDOW if self.window is None else self.window

    def kept_window(self) -> int | None:
        return self.window
