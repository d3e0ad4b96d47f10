"""``build_model``: a fresh network of the architecture a :class:`ModelConfig` names.

The model class comes from the architecture's record (:mod:`nnfmu.models.architectures`), which every
architecture registers from its own folder (the five networks, :mod:`nnfmu.networks`; ``nnfmu.ss``,
``nnfmu.hybrid``, plugins).
"""

from __future__ import annotations

from typing import Mapping

from nnfmu.errors import ShapeError
from nnfmu.models.base import StepModel
from nnfmu.models.config import ModelConfig
from nnfmu.models.ensemble import EnsembleStepModel, single_model_class


def build_model(config: ModelConfig | Mapping, meta: Mapping | None = None, norm=None) -> StepModel:
    """Build a freshly initialised network (or a registered architecture's model, e.g. a hybrid).

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
    cls = EnsembleStepModel if config.members > 1 else single_model_class(config)
    model = cls(config, meta)
    if norm is not None:
        model.set_normalisation(norm)
    return model
