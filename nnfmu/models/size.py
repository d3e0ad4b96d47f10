"""The size of a network, counted before it is built: the check behind :data:`nnfmu.limits.MAX_PARAMETERS`.

:mod:`nnfmu.limits` holds the limits and sits on the ground floor (the progress bars use it);
counting a network's parameters needs the networks, so it lives here, above them.
"""

from __future__ import annotations

import torch

from nnfmu.errors import ConfigError
from nnfmu.limits import MAX_PARAMETERS
from nnfmu.models import architectures
from nnfmu.models.registry import build_model

__all__ = ["count_parameters", "check_network_size"]


def count_parameters(model_config, meta: dict | None = None) -> int:
    """Trainable parameters of the network ``model_config`` describes, counted without allocating them."""
    config = model_config
    counting = architectures.architecture(config.arch).get("counting_config")
    if counting is not None:  # e.g. a model that would compile C while it is built
        config = counting(config)
    with torch.device("meta"):
        model = build_model(config, meta)
    return sum(p.numel() for p in model.parameters() if p.requires_grad)


def check_network_size(model_config, meta: dict | None = None) -> int:
    """Raise ConfigError if the network would exceed :data:`MAX_PARAMETERS`; return its parameter count."""
    n = count_parameters(model_config, meta)
    if n > MAX_PARAMETERS:
        c = model_config
        raise ConfigError(f"--hidden {c.hidden} with --layers {c.layers} gives a {c.arch.upper()} of {n:,} parameters "
                          f"({n * 4 / 1e9:.3g} GB in float32), above nnfmu's limit of {MAX_PARAMETERS:,} "
                          f"(nnfmu.limits.MAX_PARAMETERS); choose a smaller --hidden or --layers")
    return n
