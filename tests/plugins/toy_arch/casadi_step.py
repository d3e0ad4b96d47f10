"""The toy's step and initial state as CasADi expressions, in normalised units (its record's
``casadi_step`` and ``casadi_init``); :func:`nnfmu.export.to_casadi` adds the rest and checks them
against the torch step."""

from __future__ import annotations

import casadi as ca


def _dm(t):
    return ca.DM(t.detach().double().cpu().numpy())


def _linear(layer, v):
    return ca.mtimes(_dm(layer.weight), v) + _dm(layer.bias)


def step(model, x, un):
    """``(x_next, yn_next)`` of :meth:`ToyStepModel.step_norm` (``x``, ``un``: MX columns)."""
    c = model.config
    yn, h = x[:c.n_y], x[c.n_y:]
    y_in = ca.DM.zeros(c.n_y, 1) if c.increment else yn
    h_next = c.leak * h + (1.0 - c.leak) * ca.tanh(_linear(model.cell, ca.vertcat(h, y_in, un)))
    n = _linear(model.readout, h_next)
    if not c.skip:
        yn_next = n
    elif c.increment:
        yn_next = yn + _dm(model.increment_scale) * n
    else:
        yn_next = yn + c.skip_scale * n
    return ca.vertcat(yn_next, h_next), yn_next


def init(model, ys, us):
    """``x0 = [y0 | 0]`` (the toy has no init window: ``ys``, ``us`` hold y0 and u0)."""
    return ca.vertcat(ys[-1], ca.DM.zeros(model.config.hidden, 1))
