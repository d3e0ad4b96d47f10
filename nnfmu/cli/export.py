"""``nnfmu export CHECKPOINT -o MODEL.fmu``: a trained network, or a grey-box fit, as a standalone FMU.

A checkpoint (``.pt``) is a trained network. A ``.json`` file written by ``nnfmu fit`` is a fitted physics
model: it becomes an FMU as ``nnfmu physics-fmu`` builds one (RK4 inside doStep, Model Exchange with
directional derivatives too, the parameters tunable with the estimates as their start values).

The same command is ``python -m nnfmu.export CHECKPOINT -o MODEL.fmu`` (see
:mod:`nnfmu.export.__main__`); both share :func:`add_arguments` and :func:`export_checkpoint`.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("checkpoint", help="a checkpoint written by 'nnfmu train' (.pt), or a grey-box fit written "
                                           "by 'nnfmu fit' (.json)")
    parser.add_argument("-o", "--out", help="the .fmu file to write (default: the checkpoint's name with .fmu)")
    add_fmu_options(parser)
    add_init_window_option(parser)
    parser.add_argument("--name", help="the FMU's model name and modelIdentifier (a C identifier; default: "
                                       "the .fmu file's name, so that two models of one dataset differ)")


def add_fmu_options(parser: argparse.ArgumentParser) -> None:
    """Options every FMU-writing command shares."""
    parser.add_argument("--fmi-version", type=int, choices=[2, 3], default=2,
                        help="FMI 2.0 (default, read by every importer) or 3.0 co-simulation")
    parser.add_argument("--target-isa", metavar="ISA",
                        help="compile the binary for this -march (e.g. x86-64-v3, native); default: portable, "
                             "with AVX2+FMA or AVX-512 code chosen at load time where the CPU has it")
    parser.add_argument("--profile", choices=["fast", "exact"], default="fast",
                        help="fast (default): FMA and vectorised exp/tanh, equal to the model within 1e-12 "
                             "relative; exact: the same bits as CasADi's own evaluation (docs/fmu-speed.md)")
    parser.add_argument("--precision", choices=["float64", "float32"], default="float64",
                        help="what the step computes in (the FMU's variables stay float64); float32 is about "
                             "twice as fast for hidden sizes >= 64 (docs/fmu-speed.md)")
    parser.add_argument("--platforms", metavar="LIST",
                        help="binaries to ship, comma-separated: linux64, win64, darwin64, aarch64-linux, "
                             "aarch64-darwin (or the FMI 3 names x86_64-linux, ...), 'all', or 'host' (default: "
                             "this machine only); others are cross-compiled with Zig (extra 'cross')")
    parser.add_argument("--no-model-exchange", action="store_true",
                        help="co-simulation only, also for a continuous-time model (physics, hybrid with a "
                             "derivative correction), which otherwise offers Model Exchange too")


def add_init_window_option(parser: argparse.ArgumentParser) -> None:
    """``--init-window N`` of a physics model, a grey-box fit or a hybrid: the start state estimated in the FMU."""
    parser.add_argument("--init-window", dest="init_window", type=int, metavar="N",
                        help="physics, fit or hybrid: the FMU estimates the whole initial state (unmeasured states "
                             "too) from the N samples before the start, set as its <channel>_past parameters, by a "
                             "least-squares fit of the model over them (default: a fit's own, else 1: the init "
                             "rule from the first sample; docs/own-physics.md)")


def check_fmu_options(args: argparse.Namespace) -> None:
    """Check ``--target-isa`` with this machine's C compiler before any work, so a typo is one line that lists
    the valid values, not the compiler's stderr after minutes of identification."""
    import os
    import re

    from nnfmu.errors import ConfigError, FmuBuildError
    from nnfmu.cbuild import run_compiler

    if args.target_isa is None or args.platforms not in (None, "host"):
        return  # cross-compiled binaries: Zig judges -march per target
    try:
        run_compiler([f"-march={args.target_isa}", "-E", "-x", "c", os.devnull], what="checking --target-isa")
    except FmuBuildError as exc:
        stderr = getattr(exc, "stderr", "") or ""
        valid = re.search(r"valid (?:arguments to \S*-march=\S* switch|target CPU values) are: ([^\n]*)", stderr)
        choices = ", ".join(["native", *valid.group(1).replace(";", "").split()]) if valid else "native"
        raise ConfigError(f"--target-isa {args.target_isa!r} is not an -march value the C compiler knows; choose "
                          f"one of: {choices} (or leave it out for the portable default)") from None


def build_options(args: argparse.Namespace):
    from nnfmu.export.fmu import BuildOptions

    return BuildOptions(target_isa=args.target_isa, profile=args.profile, precision=args.precision)


def write_fmu(model, out: Path, args: argparse.Namespace) -> Path:
    """Build ``model`` into ``out`` with the command-line options and print one summary line."""
    from nnfmu.export import build_fmu

    t0 = time.perf_counter()
    binaries: list[str] = []
    with_me = model.continuous is not None and not args.no_model_exchange
    path = build_fmu(model, out, fmi_version=args.fmi_version, options=build_options(args), model_exchange=with_me,
                     platforms=args.platforms,
                     on_binary=lambda folder, seconds: binaries.append(f"{folder} {seconds:.1f} s"))
    spec = model.spec
    interfaces = "co-simulation and model exchange" if with_me else "co-simulation"
    print(f"wrote {path} (FMI {args.fmi_version}.0 {interfaces}, model {spec.name!r}, {spec.n_u} inputs, "
          f"{spec.n_y} outputs, {spec.n_p} parameters, Ts = {spec.Ts:g} s) in {time.perf_counter() - t0:.1f} s; "
          f"binaries: {', '.join(binaries)}")
    return path


def fitted_model(path: str, name: str | None = None, init_window: int | None = None):
    """The :class:`~nnfmu.system.CasadiModel` of a grey-box fit file, as ``nnfmu physics-fmu`` builds a model.

    A fit that stored its training data's input range (``report["input_range"]``) declares it as the inputs' valid
    range, as a trained network's or a hybrid's FMU does (:mod:`nnfmu.valid_range`). ``init_window``: its
    estimator's window (default: the one the fit was scored with, else 1).
    """
    import dataclasses

    from nnfmu.greybox import load_fit
    from nnfmu.physics.initial_state import estimating_model
    from nnfmu.valid_range import with_ranges

    system, report = load_fit(path)
    ranges = (report or {}).get("input_range")
    if ranges is not None:  # within the physics' own limits, where it declares them
        ranges = [(lo if v.min is None else max(lo, v.min), hi if v.max is None else min(hi, v.max))
                  for v, (lo, hi) in zip(system.inputs, ranges)]
        system = dataclasses.replace(system, inputs=with_ranges(system.inputs, ranges))
    if name is not None:
        system = dataclasses.replace(system, name=name)
    window = init_window or int(report.get("init_window") or 1)
    return estimating_model(system, expose_parameters=True, init_window=window, y_scale=report.get("output_scales"))


def _with_init_window(model, network, window: int | None):
    """A hybrid's CasADi model with the estimator of ``--init-window``: each output's error divided by its
    standard deviation in training (the hybrid's normalisation), as the fit divides by the training split's."""
    from nnfmu.errors import ConfigError
    from nnfmu.physics.initial_state import with_init_window

    trained, hybrid = model.spec.init_window, model.spec.source.get("kind") == "nnfmu-hybrid"
    if hybrid and trained > 1:  # trained from its estimator's start (nnfmu.hybrid.initial_state): it keeps it
        if window not in (None, trained):
            raise ConfigError(f"this hybrid was trained from the state its estimator fits over {trained} samples, "
                              f"and its FMU takes that window; leave --init-window out (or give {trained})")
        return model
    if not window or window == 1:
        return model
    if not hybrid:
        raise ConfigError(f"--init-window applies to physics, fits and hybrids; a network's init window is learned "
                          f"in training (nnfmu train --init-window {window}); leave --init-window out of export")
    return with_init_window(model, window, y_scale=network.y_std.detach().double().numpy(),
                            x_scale=network.physics.state_scales or None)


def default_name(out: Path) -> str:
    """The FMU's model name when ``--name`` is left out: its file's name as a C identifier (``axis-joint.fmu`` ->
    ``axis_joint``), at most :data:`~nnfmu.limits.MAX_MODEL_NAME` characters."""
    from nnfmu.identifiers import to_c_identifier
    from nnfmu.limits import MAX_MODEL_NAME

    return to_c_identifier(out.stem)[:MAX_MODEL_NAME]


def export_checkpoint(args: argparse.Namespace) -> int:
    import re

    from nnfmu.cli._outputs import check_writable
    from nnfmu.errors import ConfigError
    from nnfmu.limits import MAX_MODEL_NAME
    from nnfmu.models import load_model

    if args.name is not None and not re.fullmatch(r"[A-Za-z_][A-Za-z0-9_]*", args.name):
        raise ConfigError(f"--name must be an ASCII C identifier (letters, digits, '_'), got {args.name!r}")
    if args.name is not None and len(args.name) > MAX_MODEL_NAME:  # before the compiler fails on the file names
        raise ConfigError(f"--name has {len(args.name)} characters, above nnfmu's limit of {MAX_MODEL_NAME} "
                          "(nnfmu.limits.MAX_MODEL_NAME): it names the FMU's files; choose a shorter --name")
    check_fmu_options(args)
    out = Path(args.out) if args.out else Path(args.checkpoint).with_suffix(".fmu")
    check_writable(out)
    name = args.name or default_name(out)
    if Path(args.checkpoint).suffix.lower() == ".json":
        write_fmu(fitted_model(args.checkpoint, name, args.init_window), out, args)
        return 0
    network = load_model(args.checkpoint)  # checkpoint errors first, before the heavier export imports
    from nnfmu.export import casadi_model

    model = _with_init_window(casadi_model(network, name=name), network, args.init_window)
    write_fmu(model, out, args)
    return 0


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("export", help="export a trained network or a grey-box fit as an FMU (same as python -m "
                                      "nnfmu.export)")
    add_arguments(p)
    p.set_defaults(func=export_checkpoint)
