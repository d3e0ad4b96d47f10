"""What an architecture tells the compiled free run (:mod:`nnfmu.training.compiled_rollout`) about its network.

An architecture whose step one of the C files computes names, in its record, a function ``model -> CompiledCell``
(``Architecture.rollout_cell``): which file, which of its cells, and the network's weights in that file's order.
The codes below are the C files' own (``rollout.c``'s cell, ``window_rollout.c``'s network).
"""

from __future__ import annotations

from dataclasses import dataclass

import torch

from nnfmu.models import architectures

#: ``rollout.c``: stacked one-layer cells and a linear readout (``nnfmu_rollout_forward``'s ``cell``).
RECURRENT = "rollout"
ELMAN_TANH, ELMAN_RELU, LSTM_CELL, GRU_CELL = 0, 1, 2, 3
#: ``window_rollout.c``: layers over a window of past samples (``nnfmu_window_forward``'s ``kind``).
WINDOW = "window_rollout"
DILATED_CONV, DENSE = 0, 1


@dataclass(frozen=True)
class CompiledCell:
    """One network as a C file computes it.

    Attributes
    ----------
    library : {RECURRENT, WINDOW}
        The C file (``rollout.c`` or ``window_rollout.c``).
    code : int
        Its cell (``ELMAN_TANH`` .. ``GRU_CELL``) or network (``DILATED_CONV``, ``DENSE``).
    weights : tuple of tensors
        The network's weights in the file's order (per layer its weight and bias, or a cell's four, then the
        output layer's).
    taps : int
        ``window_rollout.c``: samples each layer reads (a convolution's kernel size, the MLP's window).
    """

    library: str
    code: int
    weights: tuple[torch.Tensor, ...]
    taps: int = 1

    def __post_init__(self) -> None:
        if self.library not in (RECURRENT, WINDOW):
            raise ValueError(f"a compiled cell's library is {RECURRENT!r} or {WINDOW!r}, got {self.library!r}")


def compiled_cell(net) -> CompiledCell:
    """The cell of ``net``'s record (``Architecture.rollout_cell``) for ``net``, a network of its model class."""
    return architectures.architecture(net.config.arch).get("rollout_cell")(net)
