"""``nnfmu train`` beyond one training, and the report: ``--seeds K`` (the best or the ensemble),
``--increment auto``, and the lines that end every run (:func:`report_end`, :func:`print_test`).

Each ``run_*`` takes the :class:`~nnfmu.cli._train_plan.TrainPlan` and returns the exit status.
"""

from __future__ import annotations


def print_test(ds, test, test_window, n: int) -> None:
    """The free-run test NRMSE from y0 and, with an init window of ``n`` samples, after it."""
    per_output = ", ".join(f"{c.name} {v:.4f}" for c, v in zip(ds.outputs, test.output_mean))
    print(f"test free-run NRMSE: {test.mean:.4f} ({per_output}), from the measured y0")
    if test_window is not None:
        print(f"test free-run NRMSE after the init window: {test_window.mean:.4f} (samples 0..{n - 1} seen, "
              f"scored from sample {n})")


def run_seeds(plan) -> int:
    """The plan's seeds (``--seeds K``, or the plan's choice): :func:`nnfmu.training.train_seeds`, with every seed's
    scores and their spread printed."""
    from nnfmu.training import train_seeds

    request, out, seeds = plan.request, plan.out, plan.seeds
    if request.resume:
        from nnfmu.errors import ConfigError

        raise ConfigError("--seeds resumes by itself (finished seeds are kept, unfinished ones continue): "
                          "drop --resume and run the same command again")
    from nnfmu.cli import Terminated
    from nnfmu.training.ensemble import seeds_folder

    try:
        result = train_seeds(plan.data, plan.model_config, plan.train_config, seeds=seeds,
                             keep=request.keep or "select", out=out, jobs=request.jobs, progress=plan.progress,
                             device=plan.device, threads=request.threads, linear=plan.linear,
                             overwrite=request.force, refit_on=plan.refit_on, more_within=plan.more_seeds_within,
                             most=plan.most_seeds)
    except (KeyboardInterrupt, Terminated):
        print(_interrupted_seeds(seeds_folder(out)))
        raise
    for note in result.notes:
        print(f"note: {note}")
    for r in result.seeds:
        test = "n/a" if r["test_nrmse"] is None else f"{r['test_nrmse']:.4f}"
        print(f"seed {r['seed']}: validation NRMSE {r['best_valid_nrmse']:.4f}, test {test}, {r['stop_reason']}")
    spread = result.spread()
    print(f"kept {_kept(result, len(result.seeds))}: validation free-run NRMSE {result.valid_nrmse:.4f}; "
          f"checkpoint {out}")
    if result.test is not None:
        print_test(plan.data, result.test, result.test_window, plan.model_config.init_window)
        print(f"the seeds' own test NRMSE: mean {spread['mean']:.4f}, min {spread['min']:.4f}, max {spread['max']:.4f}")
    return 0


def _kept(result, seeds: int) -> str:
    """What the checkpoint holds: an ensemble of how many seeds, or which seed alone (``--keep ensemble`` keeps
    one seed when fewer than two trained)."""
    members = int(getattr(result.model.config, "members", 1) or 1)
    if members > 1:
        return f"the ensemble of {members} seeds" + (f" (of {seeds})" if members < seeds else "")
    alone = [r["seed"] for r in result.seeds if r["best_valid_nrmse"] == result.valid_nrmse]
    return f"seed {alone[0]} alone (of {seeds} seeds)" if alone else f"one seed alone (of {seeds})"


def _interrupted_seeds(folder) -> str:
    """What an interrupted ``--seeds`` run kept: the seeds' checkpoints, or nothing (then its empty folder goes)."""
    kept = sorted(p.name for p in folder.glob("seed-*.pt")) if folder.is_dir() else []
    if kept:
        return (f"interrupted: the checkpoints of {', '.join(kept)} are kept in {folder}; run the same command "
                "again to continue them")
    try:
        folder.rmdir()  # made for the seeds, and still empty
    except OSError:
        pass
    return "interrupted before any seed wrote a checkpoint: nothing was kept"


def run_both_modes(plan, run_one) -> int:
    """``--increment auto``: train with and without increment mode and keep the lower validation NRMSE."""
    import shutil

    from nnfmu.errors import ConfigError
    from nnfmu.models import load_checkpoint

    out = plan.out
    if plan.request.resume:
        raise ConfigError("--increment auto trains two networks into new files: drop --resume")
    try:  # both before the first training: an architecture without increment mode (the hybrid) fails here
        configs = {mode: plan.model_config.replace(increment=mode == "increment") for mode in ("residual", "increment")}
    except ConfigError as exc:
        raise ConfigError(f"--increment auto: {exc}") from exc
    scores = {}
    for mode, config in configs.items():
        part = out.with_name(f"{out.stem}.{mode}.pt")
        print(f"--- {mode} output mode -> {part}")
        one = plan.replace(model_config=config, request=plan.request.replace(out=part), linear=None)
        status = run_seeds(one) if (plan.seeds or 1) > 1 else run_one(one)
        if status != 0:
            return status
        scores[mode] = load_checkpoint(part)["summary"]["best_valid_nrmse"]
    best = min(scores, key=scores.get)
    shutil.copyfile(out.with_name(f"{out.stem}.{best}.pt"), out)
    print(f"kept the {best} output mode (validation free-run NRMSE {scores['residual']:.4f} residual, "
          f"{scores['increment']:.4f} increment) in {out}")
    return 0


def report_end(result, linear) -> None:
    """What the user should know about how the run ended: still improving, or never better than its start (which
    is then what was kept: the kept weights are the best on validation, the start included)."""
    from nnfmu.training.plan import still_improving

    if still_improving(result.history, result.best_epoch, result.stop_reason):
        print(f"still improving when stopped (best epoch {result.best_epoch} of {result.history[-1]['epoch']}): "
              "a larger budget (--epochs or --max-minutes) may help")
    if result.best_epoch == 0:
        print(f"the training never improved on its start on validation: the kept weights are {_start(result, linear)}")
    elif getattr(result.model, "physics", None) is not None:  # a hybrid: what it gained over its start
        print(f"start: the physics as given, its correction at zero, validation free-run NRMSE "
              f"{result.history[0]['valid_nrmse']:.4f} (the kept hybrid: {result.best_valid_nrmse:.4f})")


def _start(result, linear) -> str:
    if linear is not None:
        return "the linear model's"
    if getattr(result.model, "physics", None) is not None:  # a hybrid: its correction starts at zero
        return (f"the physics' as given, its correction at zero (validation free-run NRMSE "
                f"{result.history[0]['valid_nrmse']:.4f})")
    return "the untrained network's"
