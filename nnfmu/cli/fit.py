"""``nnfmu fit PHYSICS --data DIR -o FIT.json``: grey-box identification of a physics model's parameters.

Why ``fit``: the command reads as what it does, ``nnfmu fit slider --data DIR`` (fit the slider to the
data); networks are *trained* (``nnfmu train``) and the linear model *identified* (``nnfmu linear``),
so the word is free, and the model named after it says what is fitted.

Estimates the free parameters (:func:`nnfmu.greybox.fit_greybox`), prints each with its unit and standard
error, their correlations and weakest direction, a line per parameter the data do not determine (with the
fix: ``--fixed``, or a tie in the model; :mod:`nnfmu.greybox.identifiability`), why the solver stopped, and
the NRMSE / RMSE / fit % on train and validation (test with ``--report-test``), and writes the fitted model
as JSON, which ``nnfmu export FIT.json -o X.fmu`` turns into an FMU and every ``--physics`` option takes as
a model. A flagged fit still exits 0: the file is written, and the lines say what to change.
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("fit", help="fit a physics model's free parameters to a dataset (grey-box identification)",
                       description="Estimate the free parameters of a physics model from the training split by "
                                   "simulation error: free runs over windows of the records, each window's initial "
                                   "state estimated, within the bounds; print the estimates with standard errors, "
                                   "which parameters the data cannot determine (and what to fix or tie), why the "
                                   "solver stopped, and the NRMSE of the free run on train and validation (test "
                                   "with --report-test); write the fitted model as JSON. A flagged fit exits 0.")
    p.add_argument("system", metavar="PHYSICS",
                   help="the model: a registered name (slider, valve, arm), FILE.py:NAME or a .json model")
    p.add_argument("--data", required=True, help="dataset folder (train fitted; valid scored, and test with "
                   "--report-test)")
    p.add_argument("-o", "--out", required=True, help="the fitted model to write (.json)")
    p.add_argument("--free", metavar="A,B", help="parameters to estimate (default: the model's free parameters)")
    p.add_argument("--fixed", metavar="C,D", help="parameters to hold at their values")
    p.add_argument("--bounds", metavar="NAME=LO:HI", action="append",
                   help="bounds of a parameter in its unit, either side may be empty (unbounded); repeat or "
                        "separate with commas (default: the model's min and max)")
    p.add_argument("--start", metavar="NAME=VALUE", action="append",
                   help="a parameter's starting (or, if fixed, held) value; repeat or separate with commas")
    p.add_argument("--window", type=int, default=200, metavar="N",
                   help="samples per window, each with its own estimated initial state (default 200; at most "
                        "the shortest training record)")
    p.add_argument("--starts", type=int, default=1, metavar="N",
                   help="starting points: the given start, then N-1 random ones inside the bounds (default 1)")
    p.add_argument("--seed", type=int, default=0, help="seed of the random starting points (default 0)")
    p.add_argument("--solver", choices=["trf", "ipopt"], default="trf",
                   help="trf (default): SciPy's trust-region least squares on the exact Jacobian; ipopt: CasADi's "
                        "IPOPT with the same Gauss-Newton Hessian (slower on the slider and the valve; "
                        "docs/greybox.md)")
    p.add_argument("--max-evaluations", type=int, metavar="N",
                   help="residual evaluations (trf) or iterations (ipopt) per start (default: until converged, "
                        "at most 1000; the fit says why it stopped)")
    p.add_argument("--n-sub", type=int, metavar="N", help="RK4 sub-steps per sample (default: the model's own)")
    p.add_argument("--max-windows", type=int, metavar="N",
                   help="fit on at most N windows spread evenly over the training split (default: all); for "
                        "a model whose iteration over every window takes too long")
    p.add_argument("--compile", choices=["auto", "on", "off"], default="auto",
                   help="run the windows' free runs and sensitivities as compiled C: auto (default) for large "
                        "models (the ODE's instructions times the sub-steps from 20,000, as the arm), same values")
    p.add_argument("--report-test", action="store_true",
                   help="also score the test split (default: train and validation only; choose on validation, "
                        "and look at test for the model finally chosen)")
    p.add_argument("--init-window", dest="init_window", type=int, default=1, metavar="N",
                   help="score every split after an init window of N samples, from the state that the FMU's "
                        "estimator fits to them (kept in the fit file, so 'nnfmu export' builds that FMU); "
                        "default 1: from the first sample's init rule")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=_run)


def _names(text: str | None) -> tuple[str, ...] | None:
    return None if text is None else tuple(n.strip() for n in text.split(",") if n.strip())


def _pairs(items: list[str] | None, flag: str) -> list[tuple[str, str]]:
    from nnfmu.errors import ConfigError

    out = []
    for item in (piece for given in items or [] for piece in given.split(",") if piece.strip()):
        name, sep, value = item.partition("=")
        if not sep or not name.strip():
            raise ConfigError(f"{flag} takes NAME=VALUE, got {item!r}")
        out.append((name.strip(), value.strip()))
    return out


def _number(text: str, flag: str, name: str) -> float:
    from nnfmu.errors import ConfigError

    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if not math.isfinite(value):
        raise ConfigError(f"{flag} {name}: {text!r} is not a finite number")
    return value


def parse_bounds(items: list[str] | None) -> dict:
    """``["m=0.1:10", "d=:5"]`` -> ``{"m": (0.1, 10.0), "d": (None, 5.0)}`` (ConfigError on a malformed one)."""
    from nnfmu.errors import ConfigError

    out = {}
    for name, value in _pairs(items, "--bounds"):
        lo, sep, hi = value.partition(":")
        if not sep:
            raise ConfigError(f"--bounds {name}={value}: give LO:HI (either side may be empty)")
        out[name] = tuple(None if not t.strip() else _number(t, "--bounds", name) for t in (lo, hi))
    return out


def _summary(system, report: dict) -> list[str]:
    from nnfmu.greybox.identifiability import describe

    lines = [f"{'parameter':<12} {'value':>12} {'std error':>10}  unit"]
    for name, row in report["parameters"].items():
        flag = "  (at a bound)" if row["at_bound"] else ""
        lines.append(f"{name:<12} {row['value']:>12.6g} {row['std_error']:>10.3g}  {row['unit']}{flag}")
    for split, s in report["scores"].items():
        if s.get("nrmse") is None:
            lines.append(f"{split}: {s.get('note', 'not scored')}")
            continue
        rmse = ", ".join(f"{n} {o['rmse']:.4g} {o.get('unit', '')}".rstrip() for n, o in s["outputs"].items())
        lines.append(f"{split}: NRMSE {s['nrmse']:.4f}, fit {s['fit_percent']:.1f} %, RMSE {rmse}")
    if report.get("identifiability"):
        lines += describe(report["identifiability"])
    lines.append(f"solver: {report['stopped']}")
    lines += [n for n in report["notes"] if not n.startswith(f"the {report['solver']} solver ")]
    spread = (f" (of {report['windows_in_split']}, spread over the training split)"
              if report["windows"] < report["windows_in_split"] else "")
    lines.append(f"{len(report['starts'])} start(s), {report['windows']} windows{spread} of {report['window']} "
                 f"samples, {'compiled C' if report['compiled'] else 'CasADi virtual machine'}, "
                 f"{report['seconds']:.1f} s")
    return lines


def _run(args: argparse.Namespace) -> int:
    from nnfmu.cli._outputs import check_writable
    from nnfmu.data import load_dataset
    from nnfmu.errors import ConfigError
    from nnfmu.greybox import FitConfig, fit_greybox, save_fit
    from nnfmu.physics import resolve_physics
    from nnfmu.valid_range import training_range

    config = FitConfig(free=_names(args.free), fixed=_names(args.fixed) or (), bounds=parse_bounds(args.bounds),
                       start={n: _number(v, "--start", n) for n, v in _pairs(args.start, "--start")},
                       window=args.window, starts=args.starts, seed=args.seed, solver=args.solver,
                       max_evaluations=args.max_evaluations, n_sub=args.n_sub, max_windows=args.max_windows,
                       compile=args.compile, init_window=args.init_window)
    out = Path(args.out)
    if out.suffix.lower() != ".json":  # a fit in g.pt would be taken for a checkpoint by export and info
        raise ConfigError(f"-o {out}: a fit is written as JSON; give a name ending in .json (e.g. -o "
                          f"{out.with_suffix('.json').name})")
    check_writable(out)
    system = resolve_physics(args.system)
    dataset = load_dataset(args.data)
    print(f"fit: {system.name} on {args.data} by {args.solver}, {args.starts} start(s)", flush=True)
    fit = fit_greybox(system, dataset, config, progress=not args.quiet, score_test=args.report_test)
    if config.init_window > 1:
        print(f"scores after an init window of {config.init_window} samples, from the state the FMU's estimator "
              "fits to them (as nnfmu evaluate --init-window scores its FMU)")
    print("\n".join(_summary(fit.system, fit.report)))
    report = {**fit.report, "data": str(args.data), "input_range": training_range(dataset.train.u)}  # FMU range
    print(f"wrote {save_fit(out, fit.system, report)}")
    return 0
