"""The step interface every network implements, the architecture records, and checkpoints.

- :class:`StepModel`: ``init(y0, u0) -> x0``, ``step(x, u) -> (x_next, y_next)``,
  ``model(u, y0[, y_meas])`` and ``simulate(u, y0)`` (numpy, float64); an architecture implements its
  normalised core, ``init_norm``, ``step_norm`` and ``inject_y`` (docs/design.md, "Adding an architecture")
- :class:`ModelConfig`: the fields every architecture's config shares; ``ModelConfig(arch=NAME, ...)`` builds
  the config class of ``NAME``'s record; :func:`build_model` makes a fresh network
- options of every architecture: an init window (:mod:`nnfmu.models.encoder`), increment mode,
  and ensembles of K networks fed back as one prediction (:class:`EnsembleStepModel`)
- :mod:`nnfmu.models.architectures`: one record per architecture (:class:`Architecture`), the unit of
  extension, and the only source of architecture names; the five networks (:mod:`nnfmu.networks`), the
  ss network, the hybrid and plugins each register their own
- checkpoints: :func:`load_model`, :func:`save_checkpoint`, :func:`load_checkpoint`

Each public name is declared once, by its import below; those under ``TYPE_CHECKING`` are imported on first use
(:func:`nnfmu._lazy.declared_exports`), so that the records (and ``nnfmu --help``) need no torch.
"""

from typing import TYPE_CHECKING

from nnfmu._lazy import declared_exports
from nnfmu.models.architectures import Architecture, Option, register_architecture

if TYPE_CHECKING:
    from nnfmu.models.base import StepModel
    from nnfmu.models.checkpoint import load_checkpoint, load_model, model_from_checkpoint, save_checkpoint
    from nnfmu.models.config import ACTIVATIONS, ModelConfig
    from nnfmu.models.ensemble import EnsembleStepModel
    from nnfmu.models.registry import build_model
    from nnfmu.models.window import WindowStepModel

__getattr__, __dir__, __all__ = declared_exports(globals())
