"""The architectures on the command line: ``--arch`` choices and each architecture's own options, from the records.

``nnfmu train`` and ``nnfmu tune`` offer every registered architecture (:mod:`nnfmu.models.architectures`):
the five networks, the hybrid, and those of plugins (installed packages with an ``nnfmu.architectures``
entry point, or modules named in ``NNFMU_PLUGINS``). Names are listed lazily (:class:`LazyChoices`), so
that building the parser imports neither torch nor CasADi; the records themselves are plain data.
"""

from __future__ import annotations

import argparse
import sys
from typing import Callable, Iterable, Mapping

from nnfmu.cli._checks import RULES, Rule
from nnfmu.errors import ConfigError
from nnfmu.models import architectures
from nnfmu.models.architectures import Architecture, Option

_TYPES = {"str": str, "int": int, "float": float}


class LazyChoices:
    """argparse ``choices`` computed on first use (checking a value, formatting help or an error).

    ``open_choices``: every value passes (the config checks it); the names are only listed in the help.
    """

    def __init__(self, names: Callable[[], Iterable[str]], *, open_choices: bool = False):
        self._names, self._open, self._cache = names, open_choices, None

    def _list(self) -> tuple[str, ...]:
        if self._cache is None:
            self._cache = tuple(self._names())
        return self._cache

    def __contains__(self, value) -> bool:
        return self._open or value in self._list()

    def __iter__(self):
        return iter(self._list())

    def __len__(self) -> int:
        return len(self._list())


def option_choices(option: Option):
    """The argparse ``choices`` of an architecture's option (lazy when the record names a function)."""
    if option.choices is None or isinstance(option.choices, tuple):
        return option.choices
    return LazyChoices(lambda: tuple(architectures.resolve(option.choices)()), open_choices=option.open_choices)


def add_architecture_options(p: argparse.ArgumentParser) -> dict[str, list[Option]]:
    """One argument group per architecture with options of its own; returns ``{field: [options]}`` added."""
    added: dict[str, Option] = {}
    try:
        records = architectures.records()
    except ConfigError as exc:  # a broken plugin must not break every command: say so, go on without it
        print(f"nnfmu: warning: {exc}", file=sys.stderr)
        records = architectures.records()
    for record in records:
        group = None
        for option in record.options:
            if option.flag in added:
                if added[option.flag].field != option.field:
                    raise ConfigError(f"architecture {record.name!r} registers {option.flag} for its field "
                                      f"{option.field!r}, but another architecture takes it for "
                                      f"{added[option.flag].field!r}; rename one of the options")
                continue
            group = group or p.add_argument_group(f"--arch {record.name}: {record.summary}")
            if option.bounds is not None and option.field not in RULES and ("train", option.field) not in RULES:
                lo, hi = option.bounds  # checked as every numeric option is (nnfmu.cli._checks)
                RULES[("train", option.field)] = Rule(lo, hi, lo_open=option.open_bounds[0],
                                                      hi_open=option.open_bounds[1])
            group.add_argument(option.flag, dest=option.field, type=_TYPES[option.type], default=None,
                               choices=option_choices(option), metavar=option.metavar, help=option.help)
            added[option.flag] = option
    return {o.field: o for o in added.values()}


def given(values: Mapping, record: Architecture) -> dict:
    """The options of architectures given on the command line, as ``record``'s config fields (parsed).

    ``values``: every architecture's own options that were given, by field (:func:`given_values`). Options of
    other architectures are an error that names them.
    """
    own = {o.field: o for o in record.options}
    foreign = [o for r in architectures.records() if r.name != record.name for o in r.options
               if o.field not in own and values.get(o.field) is not None]
    if foreign:
        owners = sorted({r.name for r in architectures.records() for o in r.options if o in foreign})
        raise ConfigError(f"{', '.join(dict.fromkeys(o.flag for o in foreign))} only apply to "
                          f"--arch {' or '.join(owners)}; drop them or train that architecture")
    out = {}
    for field, option in own.items():
        value = values.get(field)
        if value is not None:
            out[field] = value if option.parse is None else architectures.resolve(option.parse)(value)
    return out


def given_values(args: argparse.Namespace) -> dict:
    """Every registered architecture's own options given in ``args`` (as typed), by field."""
    fields = {o.field for r in architectures.records() for o in r.options}
    return {f: getattr(args, f) for f in fields if getattr(args, f, None) is not None}


def check_required(record: Architecture, given_fields) -> None:
    """ConfigError naming the first required option of ``record`` that was not given."""
    for option in record.options:
        if option.required and option.field not in given_fields:
            raise ConfigError(f"--arch {record.name} needs {option.flag} {option.metavar or option.field.upper()} "
                              f"({option.help.split(':')[0]})")


def tunable(record: Architecture) -> bool:
    """Whether ``nnfmu tune`` can build its configs from hyperparameters alone (no required option)."""
    return not any(o.required for o in record.options)
