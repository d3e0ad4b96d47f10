"""``nnfmu train`` at its defaults: the linear path and the training choices made from the data.

For an architecture whose record asks for it (``Architecture.data_plan``): without ``--linear-path off``
(and without ``--increment``) every network that may sit on a linear path starts on one
(:mod:`nnfmu.models.linear_path`): the linear baseline is identified on the training split first, and
the network learns a correction to it, starting from zero. The windows, batch, budget and validation
tail the user left out are chosen from the data (:mod:`nnfmu.training.plan`); the choices are printed.
A record with ``data_plan="budget"`` (the hybrid) trains on whole trajectories unless ``--truncate`` is given.

With the budget left to the plan (no ``--epochs``, ``--max-minutes``, ``--seeds``, ``--resume``), on the CPU
and with a core idle beside the training (one torch thread each), one seed per usable core (at least
:data:`DEFAULT_SEEDS`, at most :data:`MAX_PLANNED_SEEDS`) trains side by side (:func:`planned_seeds`) in the wall time
of one, and the kept model is chosen on validation alone (``--keep select``): the seed best on validation, joined
by another only where their ensemble lowers the validation NRMSE by 1 % or more (the margin against the noise of
the validation score). Averaging every seed regardless (``--keep ensemble``, the default before issue 38) had
been chosen on test scores of the development datasets, and on an unseen record where validation ranked the two
seeds 0.0066 against 0.0155 it kept a model 2.7 times worse on test than the better seed.
"""

from __future__ import annotations

import time

#: The fewest seeds the plan trains side by side (when the cores allow at least this many), and the most.
DEFAULT_SEEDS = 2
MAX_PLANNED_SEEDS = 8


def prepare(args, ds, model_config, train_config, given: dict):
    """``(dataset with its validation split, model_config, train_config, linear model or None)`` for a new run."""
    from nnfmu.models import architectures
    from nnfmu.training.plan import plan_training, valid_fraction, validation_line
    from nnfmu.training.trainer import prepare_dataset

    data_plan = architectures.architecture(model_config.arch).data_plan
    if not data_plan:
        return ds, model_config, train_config, None
    if data_plan == "budget" and "truncate" not in given:
        given = {**given, "truncate": None}
        print(f"plan: windows: whole trajectories (a {model_config.arch}'s state starts from y0 at a record's start; "
              "--truncate N cuts windows)")
    init_window = model_config.init_window
    if "valid_fraction" not in given and (frac := valid_fraction(ds, init_window)) is not None:
        train_config = train_config.replace(valid_fraction=frac)
        print(f"plan: {validation_line(ds, frac, train_config.valid_blocks)}")
    carved, notes = prepare_dataset(ds, train_config)
    for note in notes:
        print(f"note: {note}")
    linear = _linear_start(args, carved, model_config, ds.train if ds.valid is None and ds.train.n_traj == 1 else None)
    if linear is not None:
        model_config = model_config.replace(linear_order=linear.n_x)
    plan = plan_training(ds, {**given, "valid_fraction": train_config.valid_fraction}, linear=linear,
                         init_window=init_window)
    for line in plan.lines:
        print(f"plan: {line}")
    return carved, model_config, train_config.replace(**plan.changes), linear


def _linear_start(args, ds, model_config, record=None):
    """The identified linear model the network starts from, or None (``--linear-path off``, increment mode).

    ``record``: the one training record the validation tail was cut from, which the linear model is refitted
    on after choosing its order (:mod:`nnfmu.linear.identify`, step 6)."""
    from nnfmu.linear import LinearConfig, identify_linear, load_linear
    from nnfmu.models import architectures

    if args.linear_path == "off" or not architectures.architecture(model_config.arch).linear_path:
        return None
    if args.increment is not None or model_config.increment:
        print("plan: no linear path (increment mode carries the output from step to step; --linear-path off)")
        return None
    if args.linear_path != "auto":  # a linear model saved by `nnfmu linear --save FILE.json`
        linear = load_linear(args.linear_path)
        print(f"plan: linear path of {linear.n_x} states from {args.linear_path}; the network learns a correction "
              "to it, starting at zero")
        return linear
    t0 = time.process_time()
    linear = identify_linear(ds, LinearConfig(), progress=False, refit_on=record)
    refit = linear.info.get("refit")
    score = (f"{refit['nrmse_valid_before']:.4f}, then refitted on the training and validation data together" if refit
             else f"{linear.info['nrmse_valid']:.4f}")
    print(f"plan: linear path of {linear.n_x} states, the identified linear baseline (validation free-run NRMSE "
          f"{score}; {time.process_time() - t0:.1f} CPU-s); the network learns a correction to it, starting at "
          "zero (--linear-path off: the network alone)")
    return linear


def report_end(result, linear) -> None:
    """What the user should know about how the run ended: still improving, or never better than its start."""
    from nnfmu.training.plan import still_improving

    if still_improving(result.history, result.best_epoch, result.stop_reason):
        print(f"still improving when stopped (best epoch {result.best_epoch} of {result.history[-1]['epoch']}): "
              "a larger budget (--epochs or --max-minutes) may help")
    if result.best_epoch == 0:
        start = "the linear model" if linear is not None else "the untrained network"
        print(f"the training never improved on its start on validation: the kept weights are {start}'s")


def planned_seeds(args, model_config, given: dict, device) -> int | None:
    """How many seeds ``nnfmu train`` trains: ``--seeds`` if given, else one per usable core (``--threads`` each;
    :data:`DEFAULT_SEEDS` .. :data:`MAX_PLANNED_SEEDS`) where the plan chooses the budget and at least two cores are
    usable, else None (one training). The choice is printed."""
    from nnfmu.models import architectures
    from nnfmu.training import resources

    if args.seeds is not None or args.resume or args.increment == "auto" or {"epochs", "max_minutes"} & set(given):
        return args.seeds
    if architectures.architecture(model_config.arch).search_rank is None:  # the networks the search averages
        return None
    threads, cores = args.threads or 1, resources.usable_cores()
    if getattr(device, "type", "cpu") != "cpu" or cores < DEFAULT_SEEDS * threads:
        return None
    seeds = min(cores // threads, MAX_PLANNED_SEEDS)
    print(f"plan: seeds: {seeds} trained side by side ({cores} cores usable, {threads} thread each); the one best on "
          "validation is kept, joined by others only where their ensemble (the mean output fed back into each; one "
          "model, one FMU) lowers the validation NRMSE by 1 % or more (--keep ensemble: all of them; --seeds 1: one "
          "network)")
    return seeds
