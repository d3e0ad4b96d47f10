"""CasADi ``(init, step)`` of an ensemble (:mod:`nnfmu.models.ensemble`): the members side by side, mean fed back.

The members' own Functions (:func:`nnfmu.export.to_casadi`) are inlined on their slices of the
state; the ensemble's output is the mean of theirs, and it is written back into every member's
state as its newest output, in the member's normalised units, at the slot the member's
``inject_y`` writes (found by :func:`nnfmu.models.linear_path.y_slot`).
"""

from __future__ import annotations

import casadi as ca

from nnfmu.export import casadi_layers as nets
from nnfmu.models import EnsembleStepModel
from nnfmu.models.linear_path import y_slot


def inlined(fn: ca.Function, args: list) -> list:
    """``fn(*args)`` with ``fn``'s graph copied in, not called: the generated C then keeps the whole step in one
    function, which the fast build clones for AVX2 and AVX-512. A called Function becomes a C function of its
    own that is not cloned, so its matrix products ran in portable SSE2 code (issue 36: 6x slower)."""
    return fn.call(args, True, False)


def with_y(x, slot: list[int], yn):
    """The CasADi column ``x`` with its entries at ``slot`` replaced by ``yn`` (len(slot),)."""
    parts, start = [], 0
    for j, k in sorted(zip(slot, range(len(slot)))):  # contiguous slices, not one scalar per entry
        parts += [x[start:j], yn[k]]
        start = j + 1
    return ca.vertcat(*parts, x[start:])


def ensemble_to_casadi(model: EnsembleStepModel, member_to_casadi) -> tuple[ca.Function, ca.Function]:
    """``init``/``step`` of ``model`` from ``member_to_casadi(member) -> (init, step)`` of each member."""
    c = model.config
    pairs = [member_to_casadi(m) for m in model.members]
    init0 = pairs[0][0]
    ins = [ca.MX.sym(init0.name_in(i), init0.sparsity_in(i)) for i in range(init0.n_in())]
    x0 = ca.vertcat(*[inlined(init, ins)[0] for init, _ in pairs])
    init = ca.Function("init", ins, [x0], init0.name_in(), ["x0"])
    x, u = ca.MX.sym("x", model.n_x), ca.MX.sym("u", c.n_u)
    parts, offset = [], 0
    for m in model.members:
        parts.append(x[offset:offset + m.n_x])
        offset += m.n_x
    steps = [inlined(step, [part, u]) for (_, step), part in zip(pairs, parts)]
    y_next = sum(y for _, y in steps) / len(steps)
    yn_next = (y_next - nets.dm(model.y_mean)) / nets.dm(model.y_std)
    x_next = []
    for m, (xn, _) in zip(model.members, steps):
        x_next.append(with_y(xn, y_slot(m), yn_next))
    step = ca.Function("step", [x, u], [ca.vertcat(*x_next), y_next], ["x", "u"], ["x_next", "y_next"])
    return init, step
