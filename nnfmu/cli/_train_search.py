"""``nnfmu train --max-minutes N`` (without ``--epochs``, ``--patience``, ``--seeds``, ``--resume``, ``--increment``):
the budget spent on a small early-stopping search (:mod:`nnfmu.study.time_search`), reported in one table.

The search applies to architectures whose record plans everything from the data (``Architecture.data_plan`` True:
the networks, not the hybrid); ``--arch`` is then optional, and when left out the architectures with a ``search_rank`` are searched.
Every model or training option given stays fixed in every trial.
"""

from __future__ import annotations

import math

# options of ``nnfmu train`` (argparse dests) that fix a knob or an option of every trial
_FIXING = ("arch", "hidden", "layers", "window", "dropout", "init_window", "lr", "feedback_noise", "truncate")


def applies(request) -> bool:
    """Whether ``nnfmu train`` searches: ``--max-minutes`` alone, on a planned architecture, in a new run
    (``request``: a :class:`~nnfmu.cli._train_plan.TrainRequest`)."""
    options = request.train_options
    return ("max_minutes" in options and "epochs" not in options and "patience" not in options
            and request.seeds is None and not request.resume and request.increment is None and _planned(request.arch))


def _planned(arch: str | None) -> bool:
    from nnfmu.models import architectures

    return arch is None or architectures.architecture(arch).data_plan is True


def given_options(request, given=()) -> set:
    """The option names the user gave (``given`` plus the model options and ``--arch`` of ``request``) that stay
    fixed in a search."""
    named = {**request.model_options, **request.train_options, "arch": request.arch}
    return set(given) | {name for name in _FIXING if named.get(name) is not None}


def run_search(plan) -> int:
    """Search, print the table and the kept model's test NRMSE; returns the exit status.

    ``plan``: a :class:`~nnfmu.cli._train_plan.TrainPlan` whose ``search`` is set. The budget counts from
    ``plan.request.started``, the time the command started, so that it covers loading the data and identifying
    the linear model too.
    """
    from nnfmu.cli._train_variants import print_test
    from nnfmu.errors import TrainingError
    from nnfmu.study.time_search import search_for

    device, out, train_config = plan.device, plan.out, plan.train_config
    if getattr(device, "type", str(device)) != "cpu":
        print(f"note: the search trains its trials on the CPU cores, one each; --device {device} is not used")
    minutes = train_config.max_minutes
    knobs = {"arch": "--arch", "hidden": "--hidden", "lr": "--lr", "feedback_noise": "--feedback-noise",
             "truncate": "--truncate"}
    searched = [flag for name, flag in knobs.items() if name not in plan.given]
    print(f"search: {minutes:g} min over {' '.join(searched) or 'nothing (every knob given)'} in one worker a core; "
          "trial 0 is the plain training to its own stop, successive halving stops the other trials that trail at "
          "the same epoch")
    result = search_for(plan.data, minutes, model_config=plan.model_config, train_config=train_config,
                        linear=plan.linear, out=out, given=set(plan.given), seed=train_config.seed,
                        progress=plan.progress, since=plan.request.started)
    print_table(result.rows, result.members, result.usage)
    if result.stalled:
        print(f"search: {result.stalled}")
    if result.best is None:
        raise TrainingError(f"no trial of the search finished an epoch in {minutes:g} minutes; give a larger "
                            "--max-minutes, or --epochs N for one plain training")
    if len(result.members) > 1:
        scores = ", ".join(f"{v:.4f}" for v in result.member_scores)
        print(f"kept an ensemble of trials {', '.join(map(str, result.members))} (the mean output fed back, one "
              f"model): validation free-run NRMSE {result.best_valid_nrmse:.4f} (as each joined: {scores}; "
              f"{result.selection}); checkpoint {out} ({len(result.rows)} trials in {result.seconds:.0f} s)")
    else:
        kept = result.rows[result.members[0]]
        print(f"kept trial {kept['trial']} ({kept['arch']}, hidden {kept['hidden']}, lr {kept['lr']:g}, feedback "
              f"noise {kept['feedback_noise']:g}, {_window(kept['truncate'])}): validation free-run NRMSE "
              f"{result.best_valid_nrmse:.4f}; checkpoint {out} ({len(result.rows)} trials in {result.seconds:.0f} s)"
              + (f"; alone: {result.selection}" if result.selection else ""))
    if result.test is None:
        print("test free-run NRMSE: n/a (no test split, or the free run diverged)")
        return 0
    print_test(plan.data, result.test, result.test_window, result.model_config["init_window"])
    return 0


def _window(truncate) -> str:
    return "whole trajectories" if truncate is None else f"windows of {truncate}"


def _cell(value, fmt: str) -> str:
    if value is None or (isinstance(value, float) and not math.isfinite(value)):
        return "-"
    return format(value, fmt)


def print_table(rows: list, kept=(), usage: dict | None = None) -> None:
    """One row per trial: its settings and seed, epochs run, best validation NRMSE, halving's stop, CPU seconds, how it
    ended.

    ``kept``: the trials of the kept model (one, or an ensemble's), starred. ``usage``: the search's
    :attr:`~nnfmu.study.time_search.TimeSearchResult.usage`, printed below the table.
    """
    kept = tuple(kept)
    head = ("trial", "arch", "hidden", "lr", "noise", "window", "seed", "epochs", "valid NRMSE", "halved", "CPU-s",
            "end")
    table = [head]
    for r in rows:
        table.append((f"{r['trial']}{'*' if r['trial'] in kept else ''}", r["arch"], str(r["hidden"]),
                      f"{r['lr']:g}", f"{r['feedback_noise']:g}", "whole" if r["truncate"] is None else
                      str(r["truncate"]), str(r.get("seed", "-")), str(r["epochs"]), _cell(r["best_valid_nrmse"], ".4f"),
                      "stopped" if r["stopped"] else "-", _cell(r["cpu_s"], ".1f"),
                      r["status"] if r["error"] is None else f"{r['status']}: {r['error']}"))
    widths = [max(len(row[j]) for row in table) for j in range(len(head) - 1)]
    for row in table:
        print("  ".join(cell.rjust(w) if j else cell.ljust(w) for j, (cell, w) in enumerate(zip(row, widths)))
              + "  " + row[-1])
    if len(kept) == 1:
        print("* kept: chosen on validation (below: why)")
    elif kept:
        print("* kept: their ensemble, chosen greedily on validation (below: from which trials)")
    if usage:
        waited = ("" if usage.get("waited_s") is None else
                  f"; the workers spent {usage['workers_cpu_s'] - usage['cpu_s']:.0f} CPU-s besides (start, imports) "
                  f"and waited {usage['waited_s']:.0f} s for a core other processes held")
        load = "" if usage.get("load") is None else f" (machine load {usage['load']:.1f})"
        print(f"CPU: the trials used {usage['cpu_s']:.0f} CPU-s of {usage['cores']} cores x {usage['wall_s']:.0f} s, "
              f"{100 * usage['cpu_share']:.0f} %{waited}{load}")
