"""Torch networks behind one step interface: MLP, RNN, LSTM, GRU and TCN.

- :class:`StepModel`: ``init(y0, u0) -> x0``, ``step(x, u) -> (x_next, y_next)``,
  ``model(u, y0[, y_meas])`` and ``simulate(u, y0)`` (numpy, float64)
- :class:`ModelConfig`: architecture and sizes; :func:`build_model` makes a fresh network
- options of every architecture: an init window (:mod:`nnfmu.models.encoder`), increment mode,
  and ensembles of K networks fed back as one prediction (:class:`EnsembleStepModel`)
- :mod:`nnfmu.models.architectures`: one record per architecture (:class:`Architecture`), the unit of
  extension; :mod:`nnfmu.models.builtin` registers the five networks, other packages (``nnfmu.hybrid``,
  plugins) their own
- checkpoints: :func:`load_model`, :func:`save_checkpoint`, :func:`load_checkpoint`

The names below are imported on first use, so that the records (and ``nnfmu --help``) need no torch.
"""

from typing import TYPE_CHECKING

from nnfmu._lazy import lazy_exports
from nnfmu.models import builtin  # noqa: F401  (registers the five networks' records; imports no torch)
from nnfmu.models.architectures import Architecture, Option, register_architecture

_LAZY = {
    "ACTIVATIONS": "nnfmu.models.config",
    "ARCHS": "nnfmu.models.config",
    "ModelConfig": "nnfmu.models.config",
    "tcn_receptive_field": "nnfmu.models.config",
    "StepModel": "nnfmu.models.base",
    "EnsembleStepModel": "nnfmu.models.ensemble",
    "MLPStepModel": "nnfmu.models.mlp",
    "RecurrentStepModel": "nnfmu.models.recurrent",
    "TCNStepModel": "nnfmu.models.tcn",
    "WindowStepModel": "nnfmu.models.window",
    "build_model": "nnfmu.models.registry",
    "load_checkpoint": "nnfmu.models.checkpoint",
    "load_model": "nnfmu.models.checkpoint",
    "model_from_checkpoint": "nnfmu.models.checkpoint",
    "save_checkpoint": "nnfmu.models.checkpoint",
}

if TYPE_CHECKING:  # what _LAZY imports on first use, for readers and tools (mkdocstrings, type checkers)
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
    "Architecture",
    "EnsembleStepModel",
    "MLPStepModel",
    "ModelConfig",
    "Option",
    "RecurrentStepModel",
    "StepModel",
    "TCNStepModel",
    "WindowStepModel",
    "build_model",
    "load_checkpoint",
    "load_model",
    "model_from_checkpoint",
    "register_architecture",
    "save_checkpoint",
    "tcn_receptive_field",
]

__getattr__, __dir__ = lazy_exports("nnfmu.models", globals(), _LAZY)
