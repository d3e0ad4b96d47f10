"""The records of the five networks (MLP, RNN, LSTM, GRU, TCN): :mod:`nnfmu.models.architectures`.

Their config is :class:`~nnfmu.models.ModelConfig`; their CasADi step and init are in
:mod:`nnfmu.export.torch_to_casadi` and :mod:`nnfmu.export.init_window`, named lazily so that
``models`` imports nothing above it. All five run their free run as compiled C
(:mod:`nnfmu.training.compiled_rollout`). ``search_rank``: the order in which ``nnfmu train
--max-minutes`` tries them; ``grid``: the depths of the paper-size tune grid.
"""

from __future__ import annotations

from nnfmu.models.architectures import Architecture, register_architecture

_CONFIG = "nnfmu.models.config:ModelConfig"
_STEP = "nnfmu.export.torch_to_casadi:"
_INIT = "nnfmu.export.init_window:"

for _record in (
    Architecture(name="mlp", config_class=_CONFIG, model_class="nnfmu.models.mlp:MLPStepModel",
                 summary="multilayer perceptron on a window of past samples",
                 casadi_step=_STEP + "window_step", casadi_init=_INIT + "window_init", rollout_cell="mlp",
                 grid={"layers": (2, 3)}, search_rank=3),
    *(Architecture(name=arch, config_class=_CONFIG, model_class="nnfmu.models.recurrent:RecurrentStepModel",
                   summary=f"{arch.upper()} recurrent network", casadi_step=_STEP + "recurrent_step",
                   casadi_init=_INIT + "recurrent_init", rollout_cell=arch, grid={"layers": (1, 2)},
                   search_rank=rank)
      for arch, rank in (("rnn", 4), ("lstm", 1), ("gru", 0))),
    Architecture(name="tcn", config_class=_CONFIG, model_class="nnfmu.models.tcn:TCNStepModel",
                 summary="temporal convolutional network (dilated causal convolutions)",
                 casadi_step=_STEP + "tcn_step", casadi_init=_INIT + "tcn_init", rollout_cell="tcn",
                 grid={"layers": (3, 4)},
                 search_rank=2),
):
    register_architecture(_record)

