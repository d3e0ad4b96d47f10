"""The neural ODE: a continuous-time neural state-space model with no physics, as the degenerate hybrid.

::

    xdot = N(x, u) / (time_scale * Ts)       x: n_states latent states in output-normalised units
    y    = y_mean + y_std * x[:n_y]          the first n_y states are the outputs, the others are latent
    x0   = [(y0 - y_mean) / y_std, 0, ..., 0]

It is a :class:`~nnfmu.hybrid.HybridStepModel` whose physics (:func:`nnfmu.node.config.node_physics`) is a
generated zero ODE, so the hybrid's derivative correction on every state *is* the whole model: training
(the free run), checkpoints, scoring and export (an FMU with co-simulation, Model Exchange and directional
derivatives) are the hybrid's. Unlike the hybrid, and like the networks, ``nnfmu train`` plans its windows,
batch and budget from the data (a black box has no physics to tell its time scales), without a linear path.
``nnfmu train --arch node [--states N] [--time-scale SAMPLES]``.

This module registers the record only (no torch, no CasADi); the code is imported on first use.
"""

from typing import TYPE_CHECKING

# registers the hybrid first (the shared options appear under it); the physics hooks are the hybrid's
from nnfmu.hybrid import PHYSICS_OPTIONS as _PHYSICS_OPTIONS
from nnfmu.hybrid import check_device as _check_device
from nnfmu.hybrid import counting_config as _counting_config
from nnfmu._lazy import declared_exports
from nnfmu.models.architectures import Architecture as _Architecture
from nnfmu.models.architectures import Option as _Option
from nnfmu.models.architectures import register_architecture as _register

NODE_ARCH = "node"

if TYPE_CHECKING:  # each public name, declared once, imported on first use (nnfmu._lazy.declared_exports)
    from nnfmu.node.config import NodeConfig, node_physics
    from nnfmu.node.model import NodeStepModel

__getattr__, __dir__, _declared = declared_exports(globals())
__all__ = ["NODE_ARCH", *_declared]

_register(_Architecture(
    name=NODE_ARCH,
    config_class="nnfmu.node.config:NodeConfig",
    model_class="nnfmu.node.model:NodeStepModel",
    summary="a neural ODE with no physics (xdot = N(x, u), y = x[:n_y]); an FMU with Model Exchange",
    to_casadi="nnfmu.hybrid.export:hybrid_to_casadi",
    casadi_model="nnfmu.hybrid.export:hybrid_casadi_model",
    options=(
        _Option(flag="--states", field="n_states", type="int", metavar="N", bounds=(1, None),
               help="states of the neural ODE, at least the outputs' number (default: max(2 n_y, 4)); the "
                    "first n_y are the outputs, the others latent"),
        _Option(flag="--time-scale", field="time_scale", type="float", metavar="SAMPLES", bounds=(0, None),
               open_bounds=(True, False),
               help="sample times in which the network's unit output moves a state by one output standard "
                    "deviation: xdot = N(x, u) / (SAMPLES * Ts) (default 10)"),
        *_PHYSICS_OPTIONS,
    ),
    linear_path=False,
    strategies=("parallel",),
    dtype="float64",
    counting_config=_counting_config,
    check_device=_check_device,
))
