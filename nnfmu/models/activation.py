"""The hidden layers' nonlinearities by name, shared by every architecture (``config.activation``)."""

from __future__ import annotations

from torch import nn

ACTIVATION_MODULES = {"tanh": nn.Tanh, "relu": nn.ReLU, "sigmoid": nn.Sigmoid, "elu": nn.ELU, "silu": nn.SiLU}


def activation_module(name: str) -> nn.Module:
    """A fresh module of the named activation (the names of :data:`nnfmu.models.config.ACTIVATIONS`)."""
    return ACTIVATION_MODULES[name]()
