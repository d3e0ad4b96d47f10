"""The five built-in networks, each an ordinary registered architecture in its own folder.

- :mod:`nnfmu.networks.mlp`: multilayer perceptron on a window of past samples (``arch="mlp"``)
- :mod:`nnfmu.networks.recurrent`: RNN, LSTM and GRU (``arch="rnn"``, ``"lstm"``, ``"gru"``), one model class
- :mod:`nnfmu.networks.tcn`: temporal convolutional network (``arch="tcn"``)

Each folder holds its config (a :class:`~nnfmu.models.ModelConfig` subclass), its model (a
:class:`~nnfmu.models.StepModel`), its CasADi step and init (``export.py``), the cell that the compiled free run
computes it with (``rollout.py``), and its ``__init__`` registers its record through the public
:func:`~nnfmu.models.register_architecture` with its presets (``grid``, ``search_rank``), exactly as a plugin
does (docs/design.md, "Adding an architecture"). They are found as a plugin is, through the entry-point group
``nnfmu.architectures`` in pyproject.toml. The ss network (:mod:`nnfmu.ss`) is a sixth of the same kind.

Each public name is declared once, by its import below (imported on first use).
"""

from typing import TYPE_CHECKING

from nnfmu._lazy import declared_exports

if TYPE_CHECKING:
    from nnfmu.networks.mlp.config import MLPConfig
    from nnfmu.networks.mlp.model import MLPStepModel
    from nnfmu.networks.recurrent.config import RecurrentConfig
    from nnfmu.networks.recurrent.model import RecurrentStepModel
    from nnfmu.networks.tcn.config import TCNConfig, tcn_receptive_field
    from nnfmu.networks.tcn.model import TCNStepModel

__getattr__, __dir__, __all__ = declared_exports(globals())
