"""The ``init`` Function of a network in CasADi, with its init window (:mod:`nnfmu.models.encoder`).

Ports::

    init(y0[n_y], u0[n_u])                                   -> x0     (init_window = 1)
    init(y0[n_y], u0[n_u], y_past[(N-1) n_y], u_past[(N-1) n_u]) -> x0   (init_window = N > 1)

``y_past`` and ``u_past`` hold the ``N - 1`` samples before t0, oldest first, sample by sample
(``[y1, y2, ...]`` of the oldest sample, then the next one), in physical units.
"""

from __future__ import annotations

import casadi as ca

from nnfmu.export import casadi_layers as nets
from nnfmu.models import StepModel, tcn_state


def _rows(column, n_rows: int, width: int) -> list:
    """A sample-major column ``(n_rows * width, 1)`` as a list of ``n_rows`` columns ``(width, 1)``."""
    return [column[i * width:(i + 1) * width] for i in range(n_rows)]


def _last(samples: list, n: int, pad) -> list:
    """The last ``n`` of ``samples``, padded in front with ``pad`` (as :func:`nnfmu.models.encoder.last_samples`)."""
    return [pad] * max(0, n - len(samples)) + samples[max(0, len(samples) - n):]


# ``x0`` of each of the five networks from the window's normalised samples ``ys``, ``us`` (lists of columns,
# oldest first, newest = t0): the ``casadi_init`` of their records (nnfmu.models.builtin).
def recurrent_init(model, ys: list, us: list):
    """RNN/LSTM/GRU: ``[y0 | 0]`` at rest, or ``[y0 | encoder(window)]`` (:mod:`nnfmu.models.encoder`)."""
    c = model.config
    if c.init_window == 1:
        return ca.vertcat(ys[-1], ca.DM.zeros(model.n_x - c.n_y, 1))
    seen = [y - ys[-1] for y in ys] if c.increment else ys
    flat = ca.vertcat(*[ca.vertcat(y, u) for y, u in zip(seen, us)])
    return ca.vertcat(ys[-1], nets.module_expr(model.encoder, flat, "encoder"))


def tcn_init(model, ys: list, us: list):
    """TCN: the delay lines at rest, or filled from the window (:mod:`nnfmu.models.tcn_state`)."""
    L = model.config.window
    if model.config.init_window == 1:
        return _tcn_rest(model, ys[-1], us[-1])
    samples = [ca.vertcat(y, u) for y, u in zip(_last(ys[:-1], L - 1, ys[0]), _last(us[:-1], L - 1, us[0]))]
    return _tcn_from_window(model, samples, ys[-1])


def window_init(model, ys: list, us: list):
    """MLP: its window, the last ``L`` outputs and ``L - 1`` inputs (padded with the oldest sample)."""
    L = model.config.window
    return ca.vertcat(*_last(ys, L, ys[0]), *_last(us[:-1], L - 1, us[0]))


def relative_taps(columns: list, n_y: int) -> list:
    """A TCN's first-layer taps in increment mode: each column's outputs relative to the newest column's
    (as :func:`nnfmu.models.tcn_state.relative_taps`)."""
    newest = columns[-1][:n_y]
    return [ca.vertcat(col[:n_y] - newest, col[n_y:]) for col in columns]


def _tcn_column(model, i: int, taps: list):
    taps = relative_taps(taps, model.config.n_y) if i == 0 and model.config.increment else taps
    return nets.activation_expr(model.activation, nets.conv_column_expr(model.convs[i], taps), "activation")


def _tcn_rest(model, yn0, un0):
    """The rest state: each line holds the column its layer's input has when every past sample is [y0, u0]."""
    h, lines = ca.vertcat(yn0, un0), []
    for i, (n, _) in enumerate(tcn_state.line_shapes(model.config)):
        lines.append(ca.repmat(h, n, 1))
        out = _tcn_column(model, i, [h] * model.config.kernel_size)
        h = out if i == 0 else h + out
    return ca.vertcat(yn0, *lines)


def _tcn_from_window(model, samples: list, yn):
    """The delay lines from the ``L - 1`` samples ``[y_j, u_j]`` before t0 (as :func:`tcn_state.from_window`)."""
    h, lines, k = samples, [], model.config.kernel_size
    for i, (n, _) in enumerate(tcn_state.line_shapes(model.config)):
        lines += h[len(h) - n:]
        if i + 1 == model.config.layers:
            break
        d = 2 ** i
        outs = [_tcn_column(model, i, h[t - (k - 1) * d:t + 1:d]) for t in range((k - 1) * d, len(h))]
        h = outs if i == 0 else [a + b for a, b in zip(h[len(h) - len(outs):], outs)]
    return ca.vertcat(yn, *lines)


def init_function(model: StepModel, state_expr, u_mean, u_std, y_mean, y_std) -> ca.Function:
    """``init`` of ``model`` in physical units (normalisation constants as ``casadi.DM`` columns).

    ``state_expr(model, ys, us) -> x0``: its architecture's ``casadi_init`` (normalised samples, oldest first).
    """
    c = model.config
    n_past = c.init_window - 1
    y0, u0 = ca.MX.sym("y0", c.n_y), ca.MX.sym("u0", c.n_u)
    ins, names = [y0, u0], ["y0", "u0"]
    ys, us = [y0], [u0]
    if n_past:
        y_past, u_past = ca.MX.sym("y_past", n_past * c.n_y), ca.MX.sym("u_past", n_past * c.n_u)
        ins, names = ins + [y_past, u_past], names + ["y_past", "u_past"]
        ys, us = _rows(y_past, n_past, c.n_y) + ys, _rows(u_past, n_past, c.n_u) + us
    x0 = state_expr(model, [(y - y_mean) / y_std for y in ys], [(u - u_mean) / u_std for u in us])
    return ca.Function("init", ins, [x0], names, ["x0"])
