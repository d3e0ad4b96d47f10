"""``RecurrentConfig``: the config of the RNN, LSTM and GRU (``arch`` "rnn", "lstm" or "gru",
:mod:`nnfmu.networks.recurrent`)."""

from __future__ import annotations

from dataclasses import dataclass

from nnfmu.errors import ShapeError
from nnfmu.models import ModelConfig

#: ``nn.RNN`` knows only these two nonlinearities.
RNN_ACTIVATIONS = ("tanh", "relu")


@dataclass(frozen=True, kw_only=True)
class RecurrentConfig(ModelConfig):
    """:class:`~nnfmu.models.ModelConfig` of an RNN, LSTM or GRU: ``layers`` stacked cells (default 1) of
    ``hidden`` units that see one sample per step (window 1). ``activation``: the RNN's nonlinearity ('tanh' or
    'relu'); the LSTM and GRU have their fixed gate nonlinearities."""

    def resolve_window(self) -> int:
        if self.window not in (None, 1):
            raise ShapeError(f"a {self.arch.upper()} sees one sample per step (its memory is the hidden "
                             f"state), so window must be 1, got {self.window}; leave window out")
        return 1

    def activations(self) -> tuple[str, ...]:
        return RNN_ACTIVATIONS if self.arch == "rnn" else super().activations()
