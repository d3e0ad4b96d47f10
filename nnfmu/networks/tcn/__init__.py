"""The temporal convolutional network, ``nnfmu train --arch tcn``: its record only (no torch)."""

from nnfmu.models import Architecture, register_architecture

register_architecture(Architecture(
    name="tcn",
    config_class="nnfmu.networks.tcn.config:TCNConfig",
    model_class="nnfmu.networks.tcn.model:TCNStepModel",
    summary="temporal convolutional network (dilated causal convolutions)",
    casadi_step="nnfmu.networks.tcn.export:casadi_step",
    casadi_init="nnfmu.networks.tcn.export:casadi_init",
    rollout_cell="nnfmu.networks.tcn.rollout:rollout_cell",
    grid={"layers": (3, 4)},
    search_rank=2,
))
