"""A toy architecture from outside nnfmu, registered through the public record only (docs/design.md,
"Adding an architecture"); tests/test_architecture_plugin.py trains, exports and offers it.

Load it with ``NNFMU_PLUGINS=toy_arch`` (this folder's parent on ``PYTHONPATH``), or install a package
that declares it under the entry-point group ``nnfmu.architectures``. The record names its code lazily, so
importing this module costs no torch (``nnfmu --help`` stays fast).
"""

from nnfmu.models import Architecture, Option, register_architecture

register_architecture(Architecture(
    name="toy",
    config_class="toy_arch.model:ToyConfig",
    model_class="toy_arch.model:ToyStepModel",
    summary="a leaky one-layer recurrent toy (a plugin)",
    casadi_step="toy_arch.casadi_step:step",
    casadi_init="toy_arch.casadi_step:init",
    options=(Option(flag="--toy-leak", field="leak", type="float", metavar="A", bounds=(0, 1), open_bounds=(False, True),
                    help="the toy's leak: h+ = A h + (1 - A) tanh(...), 0 <= A < 1 (default 0)"),),
    preset={"hidden": 8},
    search_rank=7,  # after the built-in networks in nnfmu train --max-minutes's search
))
