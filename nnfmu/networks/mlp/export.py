"""The MLP's step and initial state as CasADi expressions in normalised units (its record's ``casadi_step``
and ``casadi_init``; state layout: :mod:`nnfmu.models.window`)."""

from __future__ import annotations

import casadi as ca

from nnfmu.export import casadi_layers as nets


def casadi_step(model, x, un):
    """``(x_next, yn_next)`` of :meth:`nnfmu.networks.mlp.model.MLPStepModel.step_norm` (``x``, ``un``: MX columns)."""
    c = model.config
    L = c.window
    ys = [x[j * c.n_y:(j + 1) * c.n_y] for j in range(L)]
    us = [x[L * c.n_y + j * c.n_u:L * c.n_y + (j + 1) * c.n_u] for j in range(L - 1)] + [un]
    seen = [y - ys[-1] for y in ys] if c.increment else ys  # increment mode: relative to the newest output
    samples = [ca.vertcat(y, u) for y, u in zip(seen, us)]
    n = nets.module_expr(model.net, ca.vertcat(*samples), "net")
    yn_next = nets.skip_expr(model, ys[-1], n)
    return ca.vertcat(*ys[1:], yn_next, *us[1:]), yn_next


def casadi_init(model, ys: list, us: list):
    """Its window, the last ``L`` outputs and ``L - 1`` inputs (padded with the oldest sample), from the init
    window's normalised columns, oldest first."""
    L = model.config.window
    return ca.vertcat(*nets.last_columns(ys, L, ys[0]), *nets.last_columns(us[:-1], L - 1, us[0]))
