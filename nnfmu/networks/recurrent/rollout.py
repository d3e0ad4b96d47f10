"""The RNN, LSTM and GRU as ``rollout.c`` computes them (their records' ``rollout_cell``,
:mod:`nnfmu.training.rollout_cells`)."""

from __future__ import annotations

from nnfmu.training.rollout_cells import ELMAN_RELU, ELMAN_TANH, GRU_CELL, LSTM_CELL, RECURRENT, CompiledCell

#: rollout.c's cell of each network (an RNN's by its nonlinearity).
_CODES = {("rnn", "tanh"): ELMAN_TANH, ("rnn", "relu"): ELMAN_RELU, "lstm": LSTM_CELL, "gru": GRU_CELL}


def rollout_cell(model) -> CompiledCell:
    """Per layer ``weight_ih, weight_hh, bias_ih, bias_hh``, then the readout's weight and bias."""
    c = model.config
    weights = [t for m in model.rnn_layers for t in (m.weight_ih_l0, m.weight_hh_l0, m.bias_ih_l0, m.bias_hh_l0)]
    code = _CODES[c.arch] if c.arch in _CODES else _CODES[(c.arch, c.activation)]
    return CompiledCell(RECURRENT, code, (*weights, model.readout.weight, model.readout.bias))
