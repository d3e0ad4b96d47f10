"""The ss network's step and initial state as CasADi expressions in normalised units (its record's
``casadi_step`` and ``casadi_init``); :func:`nnfmu.export.to_casadi` adds the normalisation, the init
window's ports and the check against the torch step."""

from __future__ import annotations

import casadi as ca

from nnfmu.export import casadi_layers as nets


def casadi_step(model, x, un):
    """``(x_next, yn_next)`` of :meth:`nnfmu.ss.model.SSStepModel.step_norm` (``x``, ``un``: MX columns)."""
    n_y = model.config.n_y
    z = x[n_y:]
    A, B, b, C, d = (nets.dm(getattr(model, k)) for k in ("lin_A", "lin_B", "lin_b", "lin_C", "lin_d"))
    f = nets.module_expr(model.f, ca.vertcat(z, un), "f")
    z_next = ca.mtimes(A, z) + ca.mtimes(B, un) + b + model.scale * f
    yn = ca.mtimes(C, z_next) + d + model.scale * nets.module_expr(model.h, z_next, "h")
    return ca.vertcat(yn, z_next), yn


def casadi_init(model, ys: list, us: list):
    """``x0 = [y0 | K_y y0 + K_u u0 + k0 + E(window)]`` from the window's columns, oldest first."""
    Ky, Ku, k0 = (nets.dm(getattr(model, k)) for k in ("lin_Ky", "lin_Ku", "lin_k0"))
    flat = ca.vertcat(*[ca.vertcat(y, u) for y, u in zip(ys, us)])
    z0 = ca.mtimes(Ky, ys[-1]) + ca.mtimes(Ku, us[-1]) + k0 + nets.module_expr(model.encoder, flat, "encoder")
    return ca.vertcat(ys[-1], z0)
