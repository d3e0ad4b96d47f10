"""``nnfmu physics-fmu SPEC -o X.fmu``: a physics model as an FMU, RK4 inside doStep, the ODE for Model Exchange.

SPEC is a registered model (:func:`nnfmu.physics.physics_names`), a model of your own ``path/to/file.py:NAME`` (loading it
runs that file's code; docs/own-physics.md) or a ``.json`` physics document or grey-box fit result. The
model is :meth:`nnfmu.physics.PhysicsSystem.model` (fixed-step RK4 with ``n_sub`` sub-steps per sample),
written by the same builder as the networks; the FMU is standalone C and never needs the model file again.
Its physical parameters become tunable FMU parameters unless ``--fixed-parameters`` bakes them in. With
``--init-window N`` its ``init`` estimates the whole state from the N samples before the start
(:mod:`nnfmu.physics.initial_state`), set as the FMU's ``<channel>_past`` parameters.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from nnfmu.cli._arch import LazyChoices
from nnfmu.cli._physics_info import physics_names
from nnfmu.cli.export import add_fmu_options, add_init_window_option, check_fmu_options, write_fmu


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("physics-fmu", help="write a physics model (built-in or your own) as an FMU",
                       description="Write a physics model as an FMU (co-simulation with RK4, and Model Exchange). "
                                   "SPEC: a registered model, path/to/file.py:NAME (runs that file's code) or a "
                                   ".json physics document or grey-box fit result.")
    p.add_argument("system", metavar="SPEC", choices=LazyChoices(physics_names, open_choices=True),
                   help="which physics model: %(choices)s, file.py:NAME or a .json")
    p.add_argument("-o", "--out", help="the .fmu file to write (default: <model name>.fmu)")
    add_fmu_options(p)
    p.add_argument("--n-sub", type=int, metavar="N",
                   help="RK4 sub-steps per sample (default: the model's own choice)")
    p.add_argument("--fixed-parameters", action="store_true",
                   help="bake the physical parameters into the code instead of exposing them")
    add_init_window_option(p)
    p.set_defaults(func=_run)


def physics_system(spec: str):
    """The :class:`nnfmu.physics.PhysicsSystem` that ``spec`` names, at its nominal parameters."""
    from nnfmu.physics import resolve_physics

    return resolve_physics(spec)


def _run(args: argparse.Namespace) -> int:
    from nnfmu.cli._outputs import check_writable

    check_fmu_options(args)
    system = physics_system(args.system)
    out = Path(args.out or f"{system.name}.fmu")
    check_writable(out)
    from nnfmu.physics.initial_state import estimating_model

    model = estimating_model(system, n_sub=args.n_sub, expose_parameters=not args.fixed_parameters,
                             init_window=args.init_window or 1)
    write_fmu(model, out, args)
    return 0
