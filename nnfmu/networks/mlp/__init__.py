"""The multilayer perceptron on a window of past samples, ``nnfmu train --arch mlp``: its record only (no torch)."""

from nnfmu.models import Architecture, register_architecture

register_architecture(Architecture(
    name="mlp",
    config_class="nnfmu.networks.mlp.config:MLPConfig",
    model_class="nnfmu.networks.mlp.model:MLPStepModel",
    summary="multilayer perceptron on a window of past samples",
    casadi_step="nnfmu.networks.mlp.export:casadi_step",
    casadi_init="nnfmu.networks.mlp.export:casadi_init",
    rollout_cell="nnfmu.networks.mlp.rollout:rollout_cell",
    grid={"layers": (2, 3)},
    search_rank=3,
))
