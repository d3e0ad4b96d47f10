"""CasADi MX expressions of the torch layers the five networks are made of.

Weights enter as dense ``casadi.DM`` constants in ``mtimes(W, v)``: CasADi's
code generator keeps them as data arrays and one dense matrix-product kernel
(which :mod:`nnfmu.export.codegen` makes vectorisable), instead of unrolling
every weight into its own instruction as SX would (step-speed.md). Dropout is
the identity, as in ``model.eval()``.
"""

from __future__ import annotations

import casadi as ca
import torch
from torch import nn

from nnfmu.errors import ExportError

# Layers :func:`module_expr` and the architecture builders know, by class.
ACTIVATIONS = (nn.Tanh, nn.ReLU, nn.Sigmoid, nn.ELU, nn.SiLU, nn.LeakyReLU)
LAYERS = (nn.Linear, nn.Conv1d, nn.RNN, nn.LSTM, nn.GRU)
IDENTITIES = (nn.Dropout, nn.Identity)
CONTAINERS = (nn.Sequential, nn.ModuleList)
SUPPORTED = LAYERS + ACTIVATIONS + IDENTITIES + CONTAINERS


def supported_names() -> str:
    return ", ".join(cls.__name__ for cls in SUPPORTED)


def unsupported(where: str, module: nn.Module) -> ExportError:
    return ExportError(f"layer {where!r} ({type(module).__name__}) cannot be exported to CasADi; "
                       f"supported layers are: {supported_names()}. Replace it, or extend nnfmu.export.casadi_layers")


def dm(t: torch.Tensor) -> ca.DM:
    """A tensor as a float64 CasADi constant (1-D tensors become column vectors)."""
    return ca.DM(t.detach().to(torch.float64).cpu().numpy())


def sigmoid(v):
    return 1 / (1 + ca.exp(-v))


def activation_expr(module: nn.Module, v, where: str):
    """Element-wise activation ``module`` applied to ``v`` (MX, any shape)."""
    if isinstance(module, nn.Tanh):
        return ca.tanh(v)
    if isinstance(module, nn.ReLU):
        return ca.fmax(v, 0)
    if isinstance(module, nn.Sigmoid):
        return sigmoid(v)
    if isinstance(module, nn.SiLU):
        return v * sigmoid(v)
    if isinstance(module, nn.ELU):  # fmin keeps exp() of large positive v out of the graph
        return ca.fmax(v, 0) + module.alpha * (ca.exp(ca.fmin(v, 0)) - 1)
    if isinstance(module, nn.LeakyReLU):
        return ca.fmax(v, 0) + module.negative_slope * ca.fmin(v, 0)
    raise unsupported(where, module)


def linear_expr(layer: nn.Linear, v):
    """``W v + b`` for a column vector (or the columns of a matrix) ``v``."""
    out = ca.mtimes(dm(layer.weight), v)
    if layer.bias is not None:
        out = out + ca.repmat(dm(layer.bias), 1, v.shape[1])
    return out


def module_expr(module: nn.Module, v, where: str):
    """Apply a Linear, an activation, a Dropout/Identity or a Sequential of them to ``v``."""
    if isinstance(module, nn.Sequential):
        for name, child in module.named_children():
            v = module_expr(child, v, f"{where}.{name}")
        return v
    if isinstance(module, nn.Linear):
        return linear_expr(module, v)
    if isinstance(module, IDENTITIES):
        return v
    return activation_expr(module, v, where)


def check_recurrent_layer(layer: nn.Module, where: str) -> None:
    if not isinstance(layer, (nn.RNN, nn.LSTM, nn.GRU)):
        raise unsupported(where, layer)
    if layer.num_layers != 1 or layer.bidirectional or getattr(layer, "proj_size", 0):
        raise ExportError(f"layer {where!r} ({type(layer).__name__}) must be one unidirectional layer without "
                          "projection; stack layers in the model's rnn_layers list instead")


def recurrent_layer_expr(layer: nn.Module, inp, h, c=None):
    """One step of a one-layer ``nn.RNN``/``nn.LSTM``/``nn.GRU`` in PyTorch's semantics -> ``(h', c')``.

    GRU: ``n = tanh(W_in x + b_in + r * (W_hn h + b_hn))``, the reset gate applied
    after the hidden matrix product, gate order r, z, n. LSTM gate order i, f, g, o.
    """
    H = layer.hidden_size
    gi = ca.mtimes(dm(layer.weight_ih_l0), inp)
    gh = ca.mtimes(dm(layer.weight_hh_l0), h)
    if layer.bias:
        gi, gh = gi + dm(layer.bias_ih_l0), gh + dm(layer.bias_hh_l0)
    if isinstance(layer, nn.GRU):
        r = sigmoid(gi[0:H] + gh[0:H])
        z = sigmoid(gi[H:2 * H] + gh[H:2 * H])
        n = ca.tanh(gi[2 * H:3 * H] + r * gh[2 * H:3 * H])
        return (1 - z) * n + z * h, None
    gates = gi + gh
    if isinstance(layer, nn.LSTM):
        i, f = sigmoid(gates[0:H]), sigmoid(gates[H:2 * H])
        g, o = ca.tanh(gates[2 * H:3 * H]), sigmoid(gates[3 * H:4 * H])
        c_next = f * c + i * g
        return o * ca.tanh(c_next), c_next
    return (ca.tanh(gates) if layer.nonlinearity == "tanh" else ca.fmax(gates, 0)), None


def conv_column_expr(conv: nn.Conv1d, taps: list):
    """One output column of a dilated convolution from its ``k`` input columns ``taps`` (oldest first):
    one ``mtimes`` of the weight, tap-major, with the stacked taps."""
    if conv.stride[0] != 1 or conv.groups != 1 or conv.padding not in ((0,), "valid"):
        raise ExportError(f"Conv1d {conv} must have stride 1, groups 1 and no padding (the window pads causally)")
    weight = conv.weight.detach().permute(0, 2, 1).reshape(conv.out_channels, -1)  # (H, k*C): tap-major columns
    out = ca.mtimes(dm(weight), ca.vertcat(*taps))
    return out + dm(conv.bias) if conv.bias is not None else out


def skip_expr(model, yn, n):
    """:meth:`nnfmu.models.StepModel.apply_skip` in CasADi: ``n``, or ``yn + scale * n`` (``skip_scale``, or in
    increment mode the per-output ``increment_scale``)."""
    if not model.config.skip:
        return n
    return yn + (dm(model.increment_scale) * n if model.config.increment else model.config.skip_scale * n)


def last_columns(columns: list, n: int, pad) -> list:
    """The last ``n`` of ``columns``, padded in front with ``pad`` (as :func:`nnfmu.models.encoder.last_samples`)."""
    return [pad] * max(0, n - len(columns)) + columns[max(0, len(columns) - n):]
