"""The subspace-encoder state-space network, ``nnfmu train --arch ss`` (:mod:`nnfmu.ss.model`).

SUBNET's model (Beintema, Schoukens and Toth, "Deep subspace encoders for nonlinear system
identification", Automatica 2023), the one behind the published black-box results on the nonlinear
benchmarks: a latent state ``z+ = A z + B u + b + f(z, u)``, an output ``y = C z + d + h(z)``, and an
encoder that estimates each window's initial state from its first samples (the FMU's init window). It
starts as the identified linear model (``linear_path="own"``: it holds the path itself) and trains on
windows whose length ``nnfmu train`` chooses from the data.

This module registers the record only (no torch, no CasADi); the code is imported on first use. It is
found through the entry-point group ``nnfmu.architectures`` (``ss = "nnfmu.ss"`` in pyproject.toml).
"""

from typing import TYPE_CHECKING

from nnfmu._lazy import declared_exports
from nnfmu.models.architectures import Architecture as _Architecture
from nnfmu.models.architectures import Option as _Option
from nnfmu.models.architectures import register_architecture as _register

if TYPE_CHECKING:  # each public name, declared once, imported on first use (nnfmu._lazy.declared_exports)
    from nnfmu.ss.config import SS_ARCH, SSConfig
    from nnfmu.ss.model import SSStepModel

__getattr__, __dir__, __all__ = declared_exports(globals())

_register(_Architecture(
    name="ss",
    config_class="nnfmu.ss.config:SSConfig",
    model_class="nnfmu.ss.model:SSStepModel",
    summary="subspace-encoder state-space network (SUBNET): z+ = A z + B u + f(z, u), y = C z + h(z), "
            "an encoder for z0",
    casadi_step="nnfmu.ss.export:casadi_step",
    casadi_init="nnfmu.ss.export:casadi_init",
    options=(_Option(flag="--ss-states", field="states", type="int", metavar="N", bounds=(1, None),
                    help="the ss network's latent states (default: the linear path's order, or max(2 n_y, 4) "
                         "without a path)"),),
    grid={"layers": (1, 2)},
    preset={"hidden": 64, "layers": 2},
    search_rank=5,
    linear_path="own",
    strategies=("parallel",),
))
