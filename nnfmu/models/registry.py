"""``build_model``: a fresh network of the architecture a :class:`ModelConfig` names."""

from __future__ import annotations

from typing import Mapping

from nnfmu.errors import ShapeError
from nnfmu.models.base import StepModel
from nnfmu.models.config import HYBRID_ARCH, ModelConfig
from nnfmu.models.mlp import MLPStepModel
from nnfmu.models.recurrent import RecurrentStepModel
from nnfmu.models.tcn import TCNStepModel

MODEL_CLASSES: dict[str, type[StepModel]] = {
    "mlp": MLPStepModel,
    "rnn": RecurrentStepModel,
    "lstm": RecurrentStepModel,
    "gru": RecurrentStepModel,
    "tcn": TCNStepModel,
}


def build_model(config: ModelConfig | Mapping, meta: Mapping | None = None, norm=None) -> StepModel:
    """Build a freshly initialised network (or hybrid model, for a :class:`nnfmu.hybrid.HybridConfig`).

    Parameters
    ----------
    config : ModelConfig or dict
        Architecture and sizes (a dict goes through :meth:`ModelConfig.from_dict`).
    meta : dict, optional
        ``Ts``, ``inputs``, ``outputs`` of the dataset (see :meth:`nnfmu.data.Dataset.meta`).
    norm : nnfmu.data.NormStats, optional
        Normalisation statistics in physical units (default: mean 0, std 1).
    """
    if isinstance(config, Mapping):
        config = ModelConfig.from_dict(config)
    if not isinstance(config, ModelConfig):
        raise ShapeError(f"expected a ModelConfig or a dict, got {type(config).__name__}")
    if config.arch == HYBRID_ARCH:  # physics + correction; the hybrid package builds on this one
        from nnfmu.hybrid.model import HybridStepModel

        model = HybridStepModel(config, meta)
    else:
        model = MODEL_CLASSES[config.arch](config, meta)
    if norm is not None:
        model.set_normalisation(norm)
    return model
