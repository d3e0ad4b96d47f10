"""Hybrid models: a CasADi physics model plus a neural correction, trained in torch and exported as one FMU.

- :class:`HybridConfig` (``arch="hybrid"``) and :class:`HybridStepModel`: physics ODE (a registered
  physics model, parameters possibly wrong) + an MLP correcting the state derivative inside the RK4 step
  (or the discrete step); physical parameters optionally trained. Built, trained, saved and
  loaded like any network (``build_model``, ``train``, ``load_model``).
- :func:`hybrid_to_casadi`, :func:`hybrid_casadi_model`: the export (also reached through
  :func:`nnfmu.export.to_casadi` and ``python -m nnfmu.export``).
- The physics in torch, written once in CasADi: :func:`casadi_to_torch` picks
  :func:`compiled_to_torch` (compiled C forward and reverse mode; fast) or :func:`sx_to_torch`
  (a :class:`TorchFunction` translating the SX instructions into torch operations).
- :func:`load_physics_params`: read a JSON parameter file (the physics models: :mod:`nnfmu.physics.registry`).

The hybrid is an architecture like the networks: this module registers its record
(:mod:`nnfmu.models.architectures`) and is found through the entry point ``nnfmu.architectures``
(``hybrid = "nnfmu.hybrid"``). Its names are imported on first use, so that registering imports
neither torch nor CasADi (``nnfmu --help`` lists the hybrid's options without them).
"""

from typing import TYPE_CHECKING

from nnfmu._lazy import declared_exports
from nnfmu.errors import ConfigError as _ConfigError
from nnfmu.limits import MAX_RK4_SUBSTEPS as _MAX_RK4_SUBSTEPS
from nnfmu.models.architectures import Architecture as _Architecture
from nnfmu.models.architectures import Option as _Option
from nnfmu.models.architectures import register_architecture as _register

if TYPE_CHECKING:  # each public name, declared once, imported on first use (nnfmu._lazy.declared_exports)
    from nnfmu.hybrid._sx_source import SUPPORTED_OPS
    from nnfmu.hybrid.casadi_torch import GRADIENT_MODES, TorchFunction, sx_to_torch
    from nnfmu.hybrid.compiled_torch import BACKENDS, CompiledFunction, casadi_to_torch, compiled_to_torch
    from nnfmu.hybrid.config import CORRECTIONS, HYBRID_ARCH, HybridConfig, load_physics_params, physics_system
    from nnfmu.hybrid.export import hybrid_casadi_model, hybrid_to_casadi
    from nnfmu.hybrid.model import HybridStepModel

__getattr__, __dir__, __all__ = declared_exports(globals())


def _names(text: str) -> tuple[str, ...]:
    """``"k_s, C_max"`` -> ``("k_s", "C_max")``; ``"none"`` (or ``""``) -> ``()``."""
    return () if text.strip().lower() == "none" else tuple(n.strip() for n in text.split(",") if n.strip())


def counting_config(config):
    """The config whose parameters are counted on torch's meta device: the physics in torch operations (the
    compiled backend would compile C first), one RK4 sub-step (the count does not depend on them; the
    construction's dry-run step of the arm's 50 took minutes there, op by op). The neural ODE's too."""
    return config.replace(physics_backend="sx", n_sub=1)


def check_device(config, device) -> None:
    if device.type != "cpu" and config.physics_backend == "compiled":
        raise _ConfigError(f"a hybrid's compiled physics runs on the CPU only, not on {device}; train it with "
                          "--physics-backend sx (the SX-to-torch translation runs on any device) or --device cpu")


# The choices below are those of nnfmu.hybrid.config (CORRECTIONS) and nnfmu.hybrid.compiled_torch (BACKENDS),
# written out so that the command line needs neither torch nor CasADi (tests/test_hybrid_cli.py compares them).
#: How a model with physics inside steps and runs it (the hybrid's and the neural ODE's options).
PHYSICS_OPTIONS = (
    _Option(flag="--n-sub", field="n_sub", type="int", metavar="N", bounds=(1, _MAX_RK4_SUBSTEPS),
           help="RK4 sub-steps per sample (default: the physics' own)"),
    _Option(flag="--physics-backend", field="physics_backend", choices=("compiled", "sx"),
           help="how torch runs the physics: compiled (C, default) or sx (torch operations; no C compiler needed)"),
)

_register(_Architecture(
    name="hybrid",
    config_class="nnfmu.hybrid.config:HybridConfig",
    model_class="nnfmu.hybrid.model:HybridStepModel",
    summary="a physics model plus a neural correction; see --physics",
    to_casadi="nnfmu.hybrid.export:hybrid_to_casadi",
    training_rollout="nnfmu.hybrid.graphed:graphed_rollout",
    casadi_model="nnfmu.hybrid.export:hybrid_casadi_model",
    options=(
        _Option(flag="--physics", field="physics", required=True, metavar="NAME|FILE.py:NAME",
               choices="nnfmu.physics.registry:physics_names", open_choices=True,
               help="the physics model the network corrects: a registered one (%(choices)s) or FILE.py:NAME, "
                    "a model of your own; also FILE.json, a grey-box fit from 'nnfmu fit', which the hybrid starts "
                    "from"),
        _Option(flag="--physics-params", field="physics_params", metavar="FILE.json",
               parse="nnfmu.hybrid.config:load_physics_params",
               help="JSON file of physical parameter values replacing the nominal ones, e.g. {\"k_s\": 32500} "
                    "(default: nominal)"),
        _Option(flag="--train-physics", field="train_physics", metavar="NAME,...", parse=_names,
               help="comma-separated physical parameters trained with the network, in log-space, or 'none' to keep "
                    "the physics as given (default: a registered model's: none; a model file's or a fit's .json: "
                    "its free parameters; when they train: --physics-schedule)"),
        _Option(flag="--correction", field="correction", choices=("derivative", "step"),
               help="where the network corrects the physics: derivative (inside every RK4 stage, default) or "
                    "step (after it)"),
        *PHYSICS_OPTIONS,
    ),
    data_plan="budget",
    linear_path=False,
    strategies=("parallel",),
    dtype="float64",
    counting_config=counting_config,
    check_device=check_device,
))
