"""The RNN, LSTM and GRU, ``nnfmu train --arch rnn|lstm|gru``: one model class, a record for each (no torch).

``search_rank``: the GRU first, then the LSTM, in ``nnfmu train --max-minutes``'s search order.
"""

from nnfmu.models import Architecture, register_architecture

for _name, _rank in (("rnn", 4), ("lstm", 1), ("gru", 0)):
    register_architecture(Architecture(
        name=_name,
        config_class="nnfmu.networks.recurrent.config:RecurrentConfig",
        model_class="nnfmu.networks.recurrent.model:RecurrentStepModel",
        summary=f"{_name.upper()} recurrent network",
        casadi_step="nnfmu.networks.recurrent.export:casadi_step",
        casadi_init="nnfmu.networks.recurrent.export:casadi_init",
        rollout_cell="nnfmu.networks.recurrent.rollout:rollout_cell",
        grid={"layers": (1, 2)},
        search_rank=_rank,
    ))
