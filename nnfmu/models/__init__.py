"""Torch networks behind one step interface: MLP, RNN, LSTM, GRU and TCN.

- :class:`StepModel`: ``init(y0, u0) -> x0``, ``step(x, u) -> (x_next, y_next)``,
  ``model(u, y0[, y_meas])`` and ``simulate(u, y0)`` (numpy, float64)
- :class:`ModelConfig`: architecture and sizes; :func:`build_model` makes a fresh network
- options of every architecture: an init window (:mod:`nnfmu.models.encoder`), increment mode,
  and ensembles of K networks fed back as one prediction (:class:`EnsembleStepModel`)
- :mod:`nnfmu.models.architectures`: the registry other packages (``nnfmu.hybrid``) add architectures to
- checkpoints: :func:`load_model`, :func:`save_checkpoint`, :func:`load_checkpoint`
"""

from nnfmu.models.base import StepModel
from nnfmu.models.checkpoint import load_checkpoint, load_model, model_from_checkpoint, save_checkpoint
from nnfmu.models.config import ACTIVATIONS, ARCHS, ModelConfig, tcn_receptive_field
from nnfmu.models.ensemble import EnsembleStepModel
from nnfmu.models.mlp import MLPStepModel
from nnfmu.models.recurrent import RecurrentStepModel
from nnfmu.models.registry import build_model
from nnfmu.models.tcn import TCNStepModel
from nnfmu.models.window import WindowStepModel

__all__ = [
    "ACTIVATIONS",
    "ARCHS",
    "EnsembleStepModel",
    "MLPStepModel",
    "ModelConfig",
    "RecurrentStepModel",
    "StepModel",
    "TCNStepModel",
    "WindowStepModel",
    "build_model",
    "load_checkpoint",
    "load_model",
    "model_from_checkpoint",
    "save_checkpoint",
    "tcn_receptive_field",
]
