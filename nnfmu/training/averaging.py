"""Weight averaging (``TrainConfig.average``): an EMA of the weights per optimiser step, or SWA per epoch.

The averaged weights are what validation scores and what the checkpoint keeps as the best
weights: averaging flattens the noise of the last optimiser steps, which on small data
(the robot) is much of the gap between a training run's best and typical epochs. Buffers
(the normalisation) are copied, not averaged.
"""

from __future__ import annotations

import contextlib
import math

import torch
from torch import nn

from nnfmu.training.config import TrainConfig


class WeightAverage:
    """The running average of a model's parameters; see the module docstring.

    Use :meth:`after_step` after every optimiser step, :meth:`after_epoch` after every epoch,
    and :meth:`applied` to evaluate the model with the averaged weights.
    """

    def __init__(self, model: nn.Module, cfg: TrainConfig):
        self.model, self.kind, self.decay = model, cfg.average, cfg.average_decay
        self.first_epoch = max(1, math.ceil(cfg.average_start * cfg.epochs)) if cfg.average == "swa" else 0
        self.count = 0
        self.params = {k: p.detach().clone() for k, p in model.named_parameters()}

    def after_step(self) -> None:
        if self.kind != "ema":
            return
        self.count += 1
        decay = min(self.decay, (1 + self.count) / (10 + self.count))  # short memory at the start (warm-up)
        with torch.no_grad():
            for k, p in self.model.named_parameters():
                self.params[k].lerp_(p.detach(), 1.0 - decay)

    def after_epoch(self, epoch: int) -> None:
        """``epoch``: the number of the epoch just finished (1-based)."""
        if self.kind != "swa" or epoch < self.first_epoch:
            return
        self.count += 1
        with torch.no_grad():
            for k, p in self.model.named_parameters():
                self.params[k].lerp_(p.detach(), 1.0 / self.count)

    @property
    def active(self) -> bool:
        """Whether the averaged weights differ from the live ones (an average has started)."""
        return self.kind != "none" and self.count > 0

    @contextlib.contextmanager
    def applied(self):
        """Swap the averaged weights into the model inside the block (a no-op before averaging starts)."""
        if not self.active:
            yield
            return
        live = {k: p.detach().clone() for k, p in self.model.named_parameters()}
        self._load(self.params)
        try:
            yield
        finally:
            self._load(live)

    def _load(self, values: dict) -> None:
        with torch.no_grad():
            for k, p in self.model.named_parameters():
                p.copy_(values[k])

    def state_dict(self) -> dict:
        return {"count": self.count, "params": {k: v.clone() for k, v in self.params.items()}}

    def load_state_dict(self, state: dict) -> None:
        self.count = int(state["count"])
        devices = {k: p.device for k, p in self.model.named_parameters()}
        self.params = {k: v.to(devices[k]).clone() for k, v in state["params"].items()}
