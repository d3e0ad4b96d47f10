"""The valid range of every numeric command-line option, checked before a command starts any work.

:func:`nnfmu.cli.run` calls :func:`check_numbers` on the parsed arguments, so ``nnfmu train --seed -5`` or
``--max-minutes 1e308`` ends in one line naming the option and its range, not in a traceback from numpy or
tqdm after the data are loaded. A rule is found by the option's ``dest`` (``--seed`` means the same in
every command) or by ``(command, dest)`` where a command differs. An option of ``type=int`` or ``float``
without a rule is refused with a message that names this module, so a new option cannot slip through
unchecked (tests/test_cli_hostile.py runs every one with hostile values).

Limits that need the data (an init window longer than the trajectories, a trajectory index beyond the
split) are checked by :func:`check_window` and :func:`check_index` once the dataset is loaded.
"""

from __future__ import annotations

import argparse
import math
import os
from dataclasses import dataclass
from typing import Callable

from nnfmu.errors import ConfigError
from nnfmu.limits import MAX_BATCH_SIZE, MAX_INIT_WINDOW, MAX_LINEAR_ORDER, MAX_RK4_SUBSTEPS, UNBOUNDED_EPOCHS

#: ``--max-minutes`` at most a year: a larger budget is a typo (and 1e308 overflows every clock).
MAX_MINUTES = 366 * 24 * 60.0
#: ``train --seeds`` at most this many trainings: ensembles gain little beyond ten, and 100 GRU trainings
#: already take hours; ``--seeds 100000`` would run for days.
MAX_SEEDS = 100
MAX_SEED = 2**32 - 1  # what every random generator in the stack (numpy, torch, Ray, Optuna) accepts
MAX_JOBS = 1024


@dataclass(frozen=True)
class Rule:
    """``lo <= value <= hi`` (``lo < value`` if ``lo_open``; ``hi`` may be a callable: a machine's cores)."""

    lo: float
    hi: float | Callable[[], float] | None = None
    lo_open: bool = False
    hi_open: bool = False
    fix: str = ""            # what to do, after "; "
    constant: str = ""       # the nnfmu.limits (or this module's) name of hi, quoted in the message

    def high(self) -> float | None:
        return self.hi() if callable(self.hi) else self.hi


def _cores() -> int:
    return os.cpu_count() or 1


_COUNT = Rule(1)
_THREADS = Rule(1, _cores, fix="use at most this machine's cores")
RULES: dict[str | tuple[str, str], Rule] = {
    "seed": Rule(0, MAX_SEED, fix="choose a seed from 0 to 4294967295"),
    "threads": _THREADS, "jobs": Rule(1, MAX_JOBS), "cpus": Rule(1, MAX_JOBS),
    # network and training (train, tune)
    "hidden": Rule(1, 100_000), "layers": Rule(1, 1000), "window": Rule(1, 100_000),
    "dropout": Rule(0, 1, hi_open=True), "init_window": Rule(1),
    "lr": Rule(0, 10, lo_open=True, fix="try the default 3e-3"), "weight_decay": Rule(0, 100),
    "clip": Rule(0, fix="0 turns clipping off"), "feedback_noise": Rule(0, 100),
    "noise": Rule(0, 10, fix="the noise std in output standard deviations, e.g. 0.01"),  # generate
    "epochs": Rule(1, UNBOUNDED_EPOCHS, fix="for a run bounded by time alone, give --max-minutes without "
                                            "--epochs", constant="nnfmu.limits.UNBOUNDED_EPOCHS"),
    "patience": Rule(0, fix="0 turns early stopping off"),
    "batch_size": Rule(1, MAX_BATCH_SIZE, constant="nnfmu.limits.MAX_BATCH_SIZE"),
    "truncate": Rule(2, fix="a window needs at least 2 samples"),
    "max_minutes": Rule(0, MAX_MINUTES, lo_open=True, constant="nnfmu.cli._checks.MAX_MINUTES"),
    "seeds": Rule(1, MAX_SEEDS, fix="each seed is a whole training; an ensemble of 5 to 10 is usual",
                  constant="nnfmu.cli._checks.MAX_SEEDS"),
    "n_sub": Rule(1, MAX_RK4_SUBSTEPS, constant="nnfmu.limits.MAX_RK4_SUBSTEPS"),
    # tune
    "samples": Rule(1, 1000), "trials": Rule(1, 100_000), "grace_epochs": Rule(1, UNBOUNDED_EPOCHS),
    "cpus_per_trial": Rule(1, MAX_JOBS), "gpus_per_trial": Rule(0, 64),
    # evaluate
    "trajectory": Rule(0, fix="trajectories are numbered from 0"), "horizon": _COUNT,
    # linear
    "order": Rule(1, MAX_LINEAR_ORDER, constant="nnfmu.limits.MAX_LINEAR_ORDER"),
    "max_order": Rule(1, MAX_LINEAR_ORDER, constant="nnfmu.limits.MAX_LINEAR_ORDER"),
    "max_evaluations": Rule(1, 10_000_000), "max_windows": Rule(1, 100_000_000),
    "order_candidates": Rule(1, MAX_LINEAR_ORDER, constant="nnfmu.limits.MAX_LINEAR_ORDER"),
    "holdout": Rule(0, 1, hi_open=True, fix="e.g. 0.2, or 0 for the whole record"),
    # fit
    "starts": Rule(1, 1000, fix="each start is a whole fit; a few spread inside the bounds are usual"),
    # the state estimated from an init window (physics, fits, hybrids)
    **{(c, "init_window"): Rule(1, MAX_INIT_WINDOW, constant="nnfmu.limits.MAX_INIT_WINDOW")
       for c in ("physics-fmu", "export", "fit")},
    # import
    "Ts": Rule(0, 366 * 86400.0, lo_open=True, fix="give the sample time in seconds"),
    "resample": Rule(1, 1_000_000), "valid_fraction": Rule(0, 1, lo_open=True, hi_open=True, fix="e.g. 0.2"),
    "valid_trajectories": Rule(1, 1_000_000), "valid_blocks": Rule(1, 1000, fix="a few blocks, e.g. 4"),
}


def _num(x: float, sep: str = "") -> str:
    """``x`` as a reader expects it: whole numbers in full (``4294967295``, ``100,000``), others as ``%g``."""
    if math.isfinite(x) and float(x).is_integer() and abs(x) < 1e16:
        return f"{int(x):{sep}}" if sep else str(int(x))
    return f"{x:g}"


def _bounds(rule: Rule, whole: bool) -> str:
    kind = "a whole number" if whole else "a finite number"
    hi = rule.high()
    lo = f"> {_num(rule.lo)}" if rule.lo_open else f">= {_num(rule.lo)}"
    if hi is None:
        return f"{kind} {lo}"
    return f"{kind} {lo} and {'<' if rule.hi_open else '<='} {_num(hi)}"


def check_value(flag: str, value, rule: Rule) -> None:
    """Raise :class:`ConfigError` naming ``flag``, its valid range and the fix if ``value`` breaks ``rule``."""
    whole = isinstance(value, int)
    hi = rule.high()
    bad = not math.isfinite(value) or value < rule.lo or (rule.lo_open and value == rule.lo)
    above = hi is not None and math.isfinite(value) and (value > hi or (rule.hi_open and value == hi))
    if above and rule.constant:
        raise ConfigError(f"{flag} {_num(value)} is above nnfmu's limit of {_num(hi, ',')} ({rule.constant}); choose a "
                          f"smaller {flag}" + (f" ({rule.fix})" if rule.fix else ""))
    if bad or above:
        fix = f"; {rule.fix}" if rule.fix and not rule.constant else ""  # with a constant, fix is for above
        raise ConfigError(f"{flag} must be {_bounds(rule, whole)}, got {value!r}{fix}")


def numeric_actions(parser: argparse.ArgumentParser) -> list[argparse.Action]:
    """The options of ``parser`` that take a number (``type=int`` or ``float``, no fixed choices)."""
    return [a for a in parser._actions if a.type in (int, float) and not a.choices]


def check_numbers(parser: argparse.ArgumentParser, args: argparse.Namespace, command: str) -> None:
    """Check every numeric option of ``command`` given in ``args`` against :data:`RULES`."""
    for action in numeric_actions(parser):
        value = getattr(args, action.dest, None)
        if value is None:
            continue
        flag = max(action.option_strings, key=len) if action.option_strings else action.dest
        rule = RULES.get((command, action.dest)) or RULES.get(action.dest)
        if rule is None:
            raise ConfigError(f"{flag} has no valid range in nnfmu.cli._checks.RULES; add one there")
        for item in value if isinstance(value, list) else [value]:
            check_value(flag, item, rule)


def check_window(flag: str, window: int | None, dataset, splits=None) -> None:
    """An init window of ``window`` samples must leave samples to run on in every trajectory of ``splits``."""
    if window is None or window <= 1:
        return
    for name in splits or dataset.splits:
        lengths = dataset.split(name).lengths
        if len(lengths) and int(min(lengths)) <= window:
            raise ConfigError(f"{flag} {window} leaves nothing to run on: the shortest trajectory of the {name} "
                              f"split has {int(min(lengths))} samples; choose {flag} below {int(min(lengths))}")


def check_training_data(model_config, train_config, dataset) -> None:
    """``nnfmu train``'s init window and ``--truncate`` windows must fit the dataset's trajectories."""
    check_window("--init-window", getattr(model_config, "init_window", None), dataset)
    n = train_config.truncate
    if n is None:
        return
    lengths = [int(v) for v in dataset.train.lengths]
    longest = sum(lengths) if train_config.join else max(lengths)
    if n > longest:
        what = "the joined training trajectories have" if train_config.join else "the longest has"
        raise ConfigError(f"--truncate {n}: no training trajectory has {n} samples ({what} {longest}); "
                          f"choose --truncate of at most {longest}")


def check_index(flag: str, index: int | None, n: int, what: str) -> None:
    """``index`` must number one of the ``n`` items described by ``what``."""
    if index is not None and not 0 <= index < n:
        raise ConfigError(f"{flag} {index} is out of range: there are {n} {what} (numbered 0 to {n - 1}); "
                          f"choose {flag} from 0 to {n - 1}")
