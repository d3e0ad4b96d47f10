"""``nnfmu physics-fmu valve|arm -o X.fmu``: a physics reference model as an FMU, RK4 inside doStep.

The model is :meth:`nnfmu.physics.PhysicsSystem.model` (fixed-step RK4 with
``n_sub`` sub-steps per sample), written by the same builder as the networks.
Its physical parameters become tunable FMU parameters unless
``--fixed-parameters`` bakes them in.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from nnfmu.cli.export import add_fmu_options, check_fmu_options, write_fmu

SYSTEMS = ("valve", "arm")


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("physics-fmu", help="write a physics reference model (valve, arm) as an FMU")
    p.add_argument("system", choices=SYSTEMS, help="which physics model")
    p.add_argument("-o", "--out", help="the .fmu file to write (default: <system>.fmu)")
    add_fmu_options(p)
    p.add_argument("--n-sub", type=int, metavar="N",
                   help="RK4 sub-steps per sample (default: the model's own choice)")
    p.add_argument("--fixed-parameters", action="store_true",
                   help="bake the physical parameters into the code instead of exposing them")
    p.set_defaults(func=_run)


def physics_system(name: str):
    """The :class:`nnfmu.physics.PhysicsSystem` called ``name`` with its nominal parameters."""
    import importlib

    from nnfmu.errors import ConfigError

    if name not in SYSTEMS:
        raise ConfigError(f"unknown physics system {name!r}; choose one of {', '.join(SYSTEMS)}")
    return getattr(importlib.import_module(f"nnfmu.physics.{name}"), f"{name}_system")()


def _run(args: argparse.Namespace) -> int:
    from nnfmu.cli._outputs import check_writable

    check_fmu_options(args)
    out = Path(args.out or f"{args.system}.fmu")
    check_writable(out)
    model = physics_system(args.system).model(n_sub=args.n_sub, expose_parameters=not args.fixed_parameters)
    write_fmu(model, out, args)
    return 0
