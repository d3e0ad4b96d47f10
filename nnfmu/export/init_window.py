"""The ``init`` Function of a network in CasADi, with its init window (:mod:`nnfmu.models.encoder`).

Ports::

    init(y0[n_y], u0[n_u])                                   -> x0     (init_window = 1)
    init(y0[n_y], u0[n_u], y_past[(N-1) n_y], u_past[(N-1) n_u]) -> x0   (init_window = N > 1)

``y_past`` and ``u_past`` hold the ``N - 1`` samples before t0, oldest first, sample by sample
(``[y1, y2, ...]`` of the oldest sample, then the next one), in physical units.
"""

from __future__ import annotations

import casadi as ca

from nnfmu.models import StepModel


def _rows(column, n_rows: int, width: int) -> list:
    """A sample-major column ``(n_rows * width, 1)`` as a list of ``n_rows`` columns ``(width, 1)``."""
    return [column[i * width:(i + 1) * width] for i in range(n_rows)]


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
