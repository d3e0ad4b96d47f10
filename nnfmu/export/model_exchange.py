"""Model Exchange for continuous-time models: the ODE, its forward derivative and its sparsity, as C and XML.

A :class:`~nnfmu.system.CasadiModel` with ``continuous`` dynamics (the physics
models, hybrids with a derivative correction) becomes an FMU that offers both
interfaces: co-simulation steps the RK4 ``step`` at Ts, and Model Exchange hands
the importer's solver the ODE itself. This module generates, beside the
``(init, step)`` code of :mod:`nnfmu.export.codegen`, a second C file with:

- ``me(x, u(, p)) -> (xdot, y)``: the right-hand side and the outputs in one call;
- ``jvp(x, u(, p), dx, du) -> (dxdot, dy)``: CasADi's forward-mode derivative of ``me``
  (``me.forward(1)``) for one seed direction in the states and inputs, which
  ``fmi2GetDirectionalDerivative`` / ``fmi3GetDirectionalDerivative`` evaluate.

:func:`continuous_structure` reads the Jacobian sparsity of the same Functions,
so the ModelStructure's dependencies (outputs on states, derivatives on states
and inputs, initial unknowns on ``<y>_start``, inputs and parameters) are what
the code computes. The C side is ``templates/nnfmu_me.c``; docs/fmu-platforms.md
describes the behaviour.
"""

from __future__ import annotations

from pathlib import Path

import casadi as ca
import numpy as np

from nnfmu.errors import FmuBuildError
from nnfmu.export.codegen import patch_source
from nnfmu.export.model_description import ContinuousStructure, FmuDescription, num
from nnfmu.system import CasadiModel

ME_C = "model_me_casadi.c"  # and model_me_casadi.h
#: Templates for every FMU with Model Exchange, and each FMI version's entry points.
ME_TEMPLATES = ("nnfmu_me.h", "nnfmu_me.c", "nnfmu_me_model.c")
ME_WRAPPER = {2: ("nnfmu_fmi2_me.c",), 3: ("nnfmu_fmi3_me.c",)}
#: Compiled (nnfmu_me_model.c includes the generated model_me_casadi.c, as nnfmu_model.c does).
ME_SOURCES = ("nnfmu_me_model.c", "nnfmu_me.c")


def _symbols(fn: ca.Function):
    sym = ca.SX if fn.is_a("SXFunction") else ca.MX
    return sym, [sym.sym(name, fn.size_in(i)) for i, name in enumerate(fn.name_in())]


def me_functions(model: CasadiModel, prefix: str) -> tuple[ca.Function, ca.Function]:
    """``me(x, u(, p)) -> (xdot, y)`` and its forward derivative ``jvp(x, u(, p), dx, du) -> (dxdot, dy)``."""
    dynamics = model.continuous
    sym, args = _symbols(dynamics.ode)
    x, params = args[0], args[2:]
    xdot, y = dynamics.ode(*args), dynamics.output(x, *params)
    names = dynamics.ode.name_in()
    me = ca.Function(f"{prefix}_me_entry_me", args, [xdot, y], names, ["xdot", "y"])
    forward = me.forward(1)
    dx, du = sym.sym("dx", x.shape[0]), sym.sym("du", args[1].shape[0])
    zero_p = [sym.zeros(p.shape[0]) for p in params]
    dxdot, dy = forward(*args, xdot, y, dx, du, *zero_p)
    jvp = ca.Function(f"{prefix}_me_entry_jvp", [*args, dx, du], [dxdot, dy], [*names, "dx", "du"],
                      ["dxdot", "dy"])
    return me, jvp


def generate_c(model: CasadiModel, directory: Path, prefix: str, *, speed_patch: bool = True,
               profile: str = "fast") -> dict[str, str]:
    """Write ``model_me_casadi.c``/``.h`` (``me`` and ``jvp``, symbols ``<prefix>_me_*``) into ``directory``;
    return their C entry points for ``nnfmu_model.h`` (macro -> symbol).

    ``profile`` is the co-simulation step's (:mod:`nnfmu.export.codegen`); the ODE and its derivatives are
    always computed in float64, whatever the step's precision: the importer's solver needs them to tolerances
    far below float32's resolution.
    """
    me, jvp = me_functions(model, prefix)
    generator = ca.CodeGenerator(ME_C, {"with_header": True, "verbose": False, "prefix": f"{prefix}_me"})
    try:
        generator.add(me)
        generator.add(jvp)
        generator.generate(str(directory) + "/")
    except RuntimeError as exc:
        raise FmuBuildError(f"CasADi cannot generate C code for the ODE of {model.spec.name!r}: {exc}; build "
                            f"the ODE from code-generatable operations") from exc
    path = Path(directory) / ME_C
    source = patch_source(path.read_text(encoding="utf-8"), speed_patch=speed_patch, profile=profile)
    path.write_text(source, encoding="utf-8")
    entry = {"NNFMU_ME": me.name(), "NNFMU_JVP": jvp.name()}
    return {**entry, **{f"{macro}_WORK": f"{symbol}_work" for macro, symbol in entry.items()}}


def _structural(fn: ca.Function, out: int, ins: dict[int, str]) -> list[tuple[tuple[str, int], ...]]:
    """Per row of output ``out`` of ``fn``: the (role, index) of the inputs it structurally depends on."""
    blocks = [(role, ca.DM(fn.jac_sparsity(out, i), 1).full() != 0) for i, role in ins.items()]
    return [tuple((role, int(j)) for role, block in blocks for j in np.flatnonzero(block[row]))
            for row in range(fn.size1_out(out))]


def continuous_structure(model: CasadiModel) -> ContinuousStructure:
    """States, nominals and the dependencies of outputs, derivatives and initial unknowns (CasADi sparsity)."""
    dynamics, spec = model.continuous, model.spec
    me, _ = me_functions(model, "structure")
    has_p = spec.n_p > 0
    sym, init_args = _symbols(model.init)
    x0 = model.init(*init_args)
    outputs = me(x0, init_args[1], *init_args[2:])
    initial_fn = ca.Function("initial", init_args, [outputs[1], x0, outputs[0]])
    knowns = {0: "output_start", 1: "input", **({2: "parameter"} if has_p else {})}
    initial = []
    for out, role in enumerate(("output", "state", "derivative")):
        initial += [((role, i), deps) for i, deps in enumerate(_structural(initial_fn, out, knowns))]
    return ContinuousStructure(
        states=dynamics.states, nominals=dynamics.nominals,
        outputs=tuple(_structural(me, 1, {0: "state"})),
        derivatives=tuple(_structural(me, 0, {0: "state", 1: "input"})),
        initial=tuple(initial))


def c_header_lines(desc: FmuDescription) -> list[str]:
    """The Model Exchange part of ``nnfmu_model.h``: value references, nominals and names of the states."""
    states, derivatives = desc.by_role("state"), desc.by_role("derivative")
    nominals = ", ".join(num(v.nominal) for v in states)
    names = ", ".join(f'"{v.name}"' for v in states)  # C identifiers (Variable checks)
    return [
        "/* Model Exchange: the ODE's states x and their derivatives (value references from these on) */",
        "#define NNFMU_MODEL_EXCHANGE 1",
        f"#define NNFMU_VR_X {states[0].value_reference}",
        f"#define NNFMU_VR_DX {derivatives[0].value_reference}",
        f"static const double nnfmu_x_nominal[{len(states)}] = {{{nominals}}};",
        f"static const char* const nnfmu_x_names[{len(states)}] = {{{names}}};",
    ]
