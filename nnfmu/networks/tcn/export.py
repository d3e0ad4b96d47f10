"""The TCN's step and initial state as CasADi expressions in normalised units (its record's ``casadi_step`` and
``casadi_init``): the incremental step on its delay lines (layout: :mod:`nnfmu.networks.tcn.state`)."""

from __future__ import annotations

import casadi as ca

from nnfmu.export import casadi_layers as nets
from nnfmu.networks.tcn import state as tcn_state


def relative_taps(columns: list, n_y: int) -> list:
    """The first layer's taps in increment mode: each column's outputs relative to the newest column's
    (as :func:`nnfmu.networks.tcn.state.relative_taps`)."""
    newest = columns[-1][:n_y]
    return [ca.vertcat(col[:n_y] - newest, col[n_y:]) for col in columns]


def casadi_step(model, x, un):
    """``(x_next, yn_next)`` of :meth:`~nnfmu.networks.tcn.model.TCNStepModel.step_norm` (``x``, ``un``: MX)."""
    c = model.config
    yn, h, offset, new_lines = x[0:c.n_y], ca.vertcat(x[0:c.n_y], un), c.n_y, []
    for i, (n, width) in enumerate(tcn_state.line_shapes(c)):
        cols = [x[offset + j * width:offset + (j + 1) * width] for j in range(n)] + [h]
        offset += n * width
        taps = relative_taps(cols, c.n_y) if i == 0 and c.increment else cols[::2 ** i]
        out = nets.activation_expr(model.activation, nets.conv_column_expr(model.convs[i], taps), "activation")
        new_lines += cols[1:]
        h = out if i == 0 else h + out
    yn_next = nets.skip_expr(model, yn, nets.linear_expr(model.head, h))
    return ca.vertcat(yn_next, *new_lines), yn_next


def casadi_init(model, ys: list, us: list):
    """The delay lines at rest, or filled from the init window's normalised columns (oldest first)."""
    L = model.config.window
    if model.config.init_window == 1:
        return _rest(model, ys[-1], us[-1])
    samples = [ca.vertcat(y, u) for y, u in zip(nets.last_columns(ys[:-1], L - 1, ys[0]),
                                                 nets.last_columns(us[:-1], L - 1, us[0]))]
    return _from_window(model, samples, ys[-1])


def _column(model, i: int, taps: list):
    taps = relative_taps(taps, model.config.n_y) if i == 0 and model.config.increment else taps
    return nets.activation_expr(model.activation, nets.conv_column_expr(model.convs[i], taps), "activation")


def _rest(model, yn0, un0):
    """The rest state: each line holds the column its layer's input has when every past sample is [y0, u0]."""
    h, lines = ca.vertcat(yn0, un0), []
    for i, (n, _) in enumerate(tcn_state.line_shapes(model.config)):
        lines.append(ca.repmat(h, n, 1))
        out = _column(model, i, [h] * model.config.kernel_size)
        h = out if i == 0 else h + out
    return ca.vertcat(yn0, *lines)


def _from_window(model, samples: list, yn):
    """The delay lines from the ``L - 1`` samples ``[y_j, u_j]`` before t0 (as :func:`tcn_state.from_window`)."""
    h, lines, k = samples, [], model.config.kernel_size
    for i, (n, _) in enumerate(tcn_state.line_shapes(model.config)):
        lines += h[len(h) - n:]
        if i + 1 == model.config.layers:
            break
        d = 2 ** i
        outs = [_column(model, i, h[t - (k - 1) * d:t + 1:d]) for t in range((k - 1) * d, len(h))]
        h = outs if i == 0 else [a + b for a, b in zip(h[len(h) - len(outs):], outs)]
    return ca.vertcat(yn, *lines)
