"""``nnfmu linear --data DIR [--order N] -o linear.fmu``: the linear state-space baseline as an FMU.

Identifies the model (:func:`nnfmu.linear.identify_linear`), prints what it
chose and how it scores, and writes an FMU (``-o``, through the one FMU
builder), the model's matrices as JSON (``--save``), or both.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from nnfmu.cli.export import add_fmu_options


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("linear", help="identify a linear state-space baseline and write it as an FMU")
    p.add_argument("--data", required=True, help="dataset folder (train split fitted; valid split, if any, "
                                                 "chooses the order and guards the refinement)")
    p.add_argument("--order", type=int, metavar="N", help="number of states (default: chosen on validation)")
    p.add_argument("--max-order", type=int, default=20, metavar="N", help="largest order tried (default 20)")
    p.add_argument("--order-candidates", type=int, default=4, metavar="N",
                   help="orders compared after a short refinement when choosing (default 4: the best subspace "
                        "model's and those at the largest singular-value gaps; 1: the subspace models decide)")
    p.add_argument("--init", choices=["estimate", "zero-offset"], default="estimate",
                   help="initial state: 'estimate' (default) reproduces y0 closest to equilibrium for u0; "
                        "'zero-offset' starts at zero with inputs and outputs relative to u0 and y0 "
                        "(the robot benchmark's convention)")
    p.add_argument("--no-refine", action="store_true", help="skip the output-error refinement")
    p.add_argument("--refine-x0", choices=["rule", "fit"], default="rule",
                   help="refinement starts each training run by the init rule (default) or fits its state")
    p.add_argument("--refine-method", choices=["quasi-newton", "gauss-newton"], default="quasi-newton",
                   help="refinement by adjoint gradients and BFGS (default; cheap evaluations) or trust-region "
                        "Gauss-Newton (the Jacobian at every evaluation)")
    p.add_argument("--max-evaluations", type=int, default=None, metavar="N",
                   help="cost evaluations allowed to the refinement (default 1000 for quasi-newton, 100 for "
                        "gauss-newton)")
    p.add_argument("--valid-fraction", dest="holdout", type=float, default=None, metavar="F",
                   help="one training record without a valid split: hold out its last F for validation (default: "
                        "the tail `nnfmu train` holds out, so that this is the model its networks start from; "
                        "0: fit the whole record and choose the order on it)")
    p.add_argument("--valid-blocks", type=int, default=1, metavar="K",
                   help="with one record: hold out --valid-fraction as K blocks spread over it instead of its tail "
                        "(default 1), as `nnfmu train --valid-blocks K` does")
    p.add_argument("--refit", action=argparse.BooleanOptionalAction, default=True,
                   help="after choosing the order and the refinement's length on validation, estimate the model "
                        "again on the training and validation data together (default; --no-refit keeps the model "
                        "fitted without the validation data)")
    p.add_argument("--join", action=argparse.BooleanOptionalAction, default=True,
                   help="where the dataset says its records are consecutive pieces of one recording (the robot), "
                        "join each split's records end to end before identifying, as `nnfmu train` joins them "
                        "(default; --no-join fits each piece from its own start)")
    p.add_argument("--threads", type=int, default=1, metavar="N",
                   help="BLAS threads (default 1: faster here, and the result does not depend on the core count)")
    p.add_argument("-o", "--out", help="the .fmu file to write")
    p.add_argument("--save", metavar="FILE", help="also (or only) write A, B, C, D and offsets as JSON")
    p.add_argument("--quiet", action="store_true", help="no progress bars (orders tried, refinement cost)")
    p.add_argument("--name", default="linear", help="the FMU's model name (a C identifier; default 'linear')")
    add_fmu_options(p)
    p.set_defaults(func=_run)


def _summary(model, dataset) -> list[str]:
    from nnfmu.metrics import nrmse

    info = model.info
    how = "forced" if info["config"]["order"] else f"chosen on the {info['scored_on']} split"
    candidates = info.get("order_candidates")
    if candidates:  # the orders compared after a short refinement (nnfmu.linear.order)
        how += ", among " + ", ".join(f"{n}: {v:.4f}" for n, v in candidates.items()) + " shortly refined"
    sv = ", ".join(f"{v:.3g}" for v in info["singular_values"][:model.n_x + 3])
    joined = info.get("joined")
    lines = [] if not joined else [
        f"records: the {joined['train']} training and {joined['valid']} validation records joined end to end (the "
        "dataset says they are consecutive pieces of one recording; --no-join keeps them apart)"]
    lines += [f"order {model.n_x} ({how}); horizon {info['horizon']}; singular values {sv}, ...",
             f"free-run NRMSE on {info['scored_on']}: subspace {info['nrmse_subspace']:.4f}"]
    refinement = info.get("refinement")
    if refinement:
        verdict = "kept" if refinement["accepted"] else "discarded, it was worse"
        lines[-1] += (f", refined {refinement['nrmse_after']:.4f} ({verdict}; "
                      f"{refinement['evaluations']} evaluations)")
    refit = info.get("refit")
    if refit:
        lines.append(f"refit on the training and validation data together ({refit['samples']} samples in "
                     f"{refit['records']} record{'s' if refit['records'] > 1 else ''}, order {model.n_x}, "
                     f"{refit['evaluations']} refinement evaluations as chosen on validation; --no-refit: without)")
    lines.append(f"spectral radius {info['spectral_radius']:.6f}; init rule '{model.init}'")
    if "test" in dataset.splits:
        test = dataset.test
        preds = [model.simulate(u, y[0]) for u, y in zip(test.u, test.y)]
        lines.append(f"free-run NRMSE on test: {nrmse(list(test.y), preds).mean:.4f}")
    return lines


def _plan(args: argparse.Namespace, config, dataset) -> str:
    """The line printed before the identification: what it will try (it may take minutes)."""
    line = f"linear: identifying on {args.data}: " + (f"order {args.order}" if args.order else
                                                      f"orders up to {args.max_order}")
    if args.no_refine:
        return line
    if not args.order and config.order_candidates > 1 and dataset.valid is not None:
        line += f" (up to {config.order_candidates} compared after {max(1, config.evaluations // 10)} " \
                "refinement evaluations each)"
    return line + f", then up to {config.evaluations} refinement evaluations (may take minutes)"


def _held_out(dataset, fraction: float | None, blocks: int = 1):
    """``(dataset, record)``: ``dataset`` with the validation tail of its one training record carved as ``nnfmu
    train`` carves it, and that whole record (for the refit); else ``(dataset, None)``.

    Only a dataset with one training record and no valid split changes; ``fraction`` None: the plan's tail
    (:func:`nnfmu.training.plan.valid_fraction`), 0: none."""
    from nnfmu.training.plan import valid_fraction, validation_line

    if dataset.valid is not None or dataset.train.n_traj != 1 or fraction == 0.0:
        return dataset, None
    fraction = valid_fraction(dataset) if fraction is None else fraction
    print(f"linear: {validation_line(dataset, fraction, blocks)}; the order is chosen and the refinement stopped on "
          "it, as in `nnfmu train`, then the model is fitted again on the whole record (--valid-fraction 0: the "
          "whole record throughout)")
    return dataset.with_validation(fraction, blocks=blocks), dataset.train


def _check_varies(dataset) -> None:
    """Refuse training data whose inputs and outputs are all constant: they show no dynamics to identify."""
    import numpy as np

    from nnfmu.errors import DataError

    train = dataset.train
    if all(np.ptp(np.concatenate(arrays), axis=0).max() == 0 for arrays in (train.u, train.y)):
        raise DataError("the training data show no dynamics (every input and output is constant); a linear model "
                        "needs data that vary: check the dataset's signals")


def _run(args: argparse.Namespace) -> int:
    from nnfmu.cli._outputs import all_or_nothing, check_writable
    from nnfmu.data import load_dataset
    from nnfmu.errors import ConfigError
    from nnfmu.identifiers import is_c_identifier
    from nnfmu.linear import LinearConfig, identify_linear

    if not args.out and not args.save:
        raise ConfigError("nothing to write; give -o MODEL.fmu for an FMU, --save MODEL.json for the matrices, "
                          "or both")
    if not is_c_identifier(args.name):
        raise ConfigError(f"--name must be a C identifier (letters, digits, '_'), got {args.name!r}")
    config = LinearConfig(order=args.order, max_order=args.max_order, init=args.init,
                          order_candidates=args.order_candidates, refine=not args.no_refine,
                          refine_x0=args.refine_x0, refine_method=args.refine_method,
                          max_evaluations=args.max_evaluations, threads=args.threads, refit=args.refit,
                          join=args.join)
    if args.out:
        from nnfmu.cli.export import check_fmu_options

        check_fmu_options(args)
    dataset, record = _held_out(load_dataset(args.data), args.holdout, args.valid_blocks)
    check_writable(args.out, args.save)  # both targets before the identification, which takes minutes
    _check_varies(dataset)  # before the plan and the progress bars: their lines would precede the error
    print(_plan(args, config, dataset), flush=True)  # --quiet is not silent until the result
    model = identify_linear(dataset, config, progress=not args.quiet, refit_on=record)
    print("\n".join(_summary(model, dataset)))
    with all_or_nothing(args.out, args.save):  # a failing --save removes the FMU just written, and the reverse
        if args.out:
            from nnfmu.cli.export import write_fmu

            write_fmu(model.casadi_model(name=args.name), Path(args.out), args)
        if args.save:
            print(f"wrote {model.save(args.save)}")
    return 0
