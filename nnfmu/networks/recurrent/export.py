"""The RNN's, LSTM's and GRU's step and initial state as CasADi expressions in normalised units (their records'
``casadi_step`` and ``casadi_init``; state layout: :mod:`nnfmu.networks.recurrent.model`)."""

from __future__ import annotations

import casadi as ca

from nnfmu.export import casadi_layers as nets


def casadi_step(model, x, un):
    """``(x_next, yn_next)`` of :meth:`~nnfmu.networks.recurrent.model.RecurrentStepModel.step_norm`."""
    c = model.config
    yn = x[0:c.n_y]
    n_blocks = c.layers * (2 if model.is_lstm else 1)
    hidden = [x[c.n_y + i * c.hidden:c.n_y + (i + 1) * c.hidden] for i in range(n_blocks)]
    hs, cs = (hidden[:c.layers], hidden[c.layers:]) if model.is_lstm else (hidden, [None] * c.layers)
    inp, new_h, new_c = ca.vertcat(ca.DM.zeros(c.n_y, 1) if c.increment else yn, un), [], []
    for i, layer in enumerate(model.rnn_layers):
        nets.check_recurrent_layer(layer, f"rnn_layers.{i}")
        h, cell = nets.recurrent_layer_expr(layer, inp, hs[i], cs[i])
        new_h.append(h)
        if cell is not None:
            new_c.append(cell)
        inp = h
    yn_next = nets.skip_expr(model, yn, nets.linear_expr(model.readout, inp))
    return ca.vertcat(yn_next, *new_h, *new_c), yn_next


def casadi_init(model, ys: list, us: list):
    """``[y0 | 0]`` at rest, or ``[y0 | encoder(window)]`` (:mod:`nnfmu.models.encoder`), from the init window's
    normalised columns, oldest first."""
    c = model.config
    if c.init_window == 1:
        return ca.vertcat(ys[-1], ca.DM.zeros(model.n_x - c.n_y, 1))
    seen = [y - ys[-1] for y in ys] if c.increment else ys
    flat = ca.vertcat(*[ca.vertcat(y, u) for y, u in zip(seen, us)])
    return ca.vertcat(ys[-1], nets.module_expr(model.encoder, flat, "encoder"))
