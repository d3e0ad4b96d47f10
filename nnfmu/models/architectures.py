"""Architectures, the unit of extension: one registration record holds all the toolkit knows about one.

An architecture is a config class, a model class (a :class:`~nnfmu.models.StepModel`) and how to
export, train, search and offer it on the command line. Its package registers one
:class:`Architecture` record when it is imported::

    register_architecture(Architecture(
        name="toy", config_class="toy_arch.model:ToyConfig", model_class="toy_arch.model:ToyStepModel",
        casadi_step="toy_arch.export:casadi_step", casadi_init="toy_arch.export:casadi_init"))

and every part of the toolkit looks the record up by the config's ``arch`` (:func:`architecture`), or
asks the records which names have a capability (:func:`names`, :func:`search_order`): the records are
the only source of architecture names, and nothing outside an architecture's own folder tests its name
or its class (tests/test_name_lists.py greps for it). The record names classes and functions either
directly or lazily as ``"module:attribute"`` strings, imported on first use (:func:`resolve`), so that
registering costs no import of torch or CasADi and ``nnfmu --help`` stays fast; :func:`check_references`
resolves them all (a test runs it on every record, so a renamed function fails a test, not a user).

Where the records come from: every architecture, built in or not, registers its own when its package is
imported, and :func:`load_plugins` imports the packages that the entry-point group ``nnfmu.architectures``
names (an installed package: entry name = architecture, value = module; nnfmu's own ``pyproject.toml``
names the five networks, :mod:`nnfmu.networks`, the ss network, the hybrid and the neural ODE) and those
listed in the environment variable ``NNFMU_PLUGINS``
  (module names separated by commas, importable from ``sys.path``/``PYTHONPATH``; how a command-line
  user loads an architecture that is not installed as a package). A lookup of an unknown name
  loads them first, so a checkpoint that names a plugin's architecture loads by itself.

This module imports neither torch nor CasADi nor any architecture.
"""

from __future__ import annotations

import importlib
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Any, Callable, Mapping, TypeAlias, Union

from nnfmu.errors import ConfigError
from nnfmu.plugins import PLUGINS_ENV, import_once, plugin_modules
from nnfmu.identifiers import is_c_identifier

__all__ = ["ENTRY_POINT_GROUP", "PLUGINS_ENV", "Architecture", "Option", "Ref", "architecture",
           "check_references", "config_class", "is_architecture", "load_plugins", "model_class", "names", "records",
           "register_architecture", "resolve", "search_order"]

ENTRY_POINT_GROUP = "nnfmu.architectures"

#: A class or function given directly, or lazily as ``"package.module:attribute"`` (:func:`resolve`).
Ref: TypeAlias = Union[type, Callable[..., Any], str]


def resolve(ref: Ref):
    """The object ``ref`` names: ``"module:attr.sub"`` imported on first use; anything else returned as is."""
    if not isinstance(ref, str):
        return ref
    module, sep, attr = ref.partition(":")
    if not sep:
        raise ConfigError(f"an architecture record names {ref!r}; write a lazy reference as 'package.module:name'")
    obj = importlib.import_module(module)
    for part in attr.split("."):
        obj = getattr(obj, part)
    return obj


@dataclass(frozen=True, kw_only=True)
class Option:
    """One command-line option of ``nnfmu train`` that an architecture's config adds (``--flag`` -> ``field``).

    ``type``: ``"str"``, ``"int"`` or ``"float"``. ``choices``: a tuple, or a reference to a function
    returning the names; ``open_choices``: the names are listed in the help but any value passes on to
    the config, which checks it (e.g. a physics model given as ``FILE.py:NAME``). ``parse``: a reference
    to ``str -> value`` applied before the value reaches the config (e.g. reading a file).
    ``required``: ``nnfmu train --arch NAME`` refuses to start without it. ``bounds``: a numeric option's
    valid range ``(lo, hi)`` (``hi`` None: no upper limit), checked before any work like every numeric
    option of the command line (:mod:`nnfmu.cli._checks`); ``open_bounds``: whether ``lo`` and ``hi`` are
    excluded.
    """

    flag: str
    field: str
    help: str
    type: str = "str"
    choices: tuple | Ref | None = None
    open_choices: bool = False
    metavar: str | None = None
    parse: Ref | None = None
    required: bool = False
    bounds: tuple[float, float | None] | None = None
    open_bounds: tuple[bool, bool] = (False, False)

    def __post_init__(self) -> None:
        if self.type not in ("str", "int", "float"):
            raise ConfigError(f"option {self.flag}: type must be 'str', 'int' or 'float', got {self.type!r}")
        if self.type != "str" and self.bounds is None:
            raise ConfigError(f"option {self.flag}: a numeric option needs its valid range, bounds=(lo, hi)")


@dataclass(frozen=True, kw_only=True)
class Architecture:
    """Everything the toolkit needs to know about one architecture.

    Attributes
    ----------
    name : str
        The ``arch`` of its configs, ``nnfmu train --arch NAME``.
    config_class, model_class : class or ``"module:attr"``
        The frozen config (a :class:`~nnfmu.models.ModelConfig` subclass) and the :class:`~nnfmu.models.StepModel`
        built from it, ``model_class(config, meta)``.
    summary : str
        A few words for ``--arch``'s help.
    casadi_step : ``(model, x, un) -> (x_next, yn_next)``, optional
        The step as CasADi MX expressions in normalised units (``x``: the flat state, ``un``: the normalised
        input column); :func:`nnfmu.export.to_casadi` adds the normalisation, ``init`` and the check against torch.
    casadi_init : ``(model, ys, us) -> x0``, optional
        The initial state from the init window's normalised samples (lists of columns, oldest first,
        the newest ``y0``, ``u0``; one each without an init window).
    to_casadi, casadi_model : ``(model, *, verify) -> (init, step)``, ``(model, *, name) -> CasadiModel``, optional
        A whole export instead of ``casadi_step``/``casadi_init`` (a model with ports of its own, such as the
        hybrid's physical parameters), used by :func:`nnfmu.export.to_casadi` and :func:`~nnfmu.export.casadi_model`.
    rollout_cell : ``model -> CompiledCell``, optional
        The cell of the compiled free run (:mod:`nnfmu.training.compiled_rollout`) that computes this
        architecture's step, for a model of exactly ``model_class``: which C file and cell, and the weights in its
        order (:class:`nnfmu.training.rollout_cells.CompiledCell`); None: torch runs the free run.
    training_rollout : ``model -> free_run or None``, optional
        A faster free run of one training batch, ``free_run(un, yn, past=None) -> (B, T, n_y)`` from ``yn[:, 0]``,
        or None where it does not apply; the trainer calls it once per batch and back-propagates before the next
        call (e.g. the hybrid's CUDA graphs, :mod:`nnfmu.hybrid.graphed`).
    options : tuple of Option
        Options of ``nnfmu train`` that only this architecture takes (its own config fields).
    grid : mapping field -> values
        The architecture's own part of the paper-size tune grid (e.g. ``{"layers": (1, 2)}``).
    preset : mapping field -> value
        The hyperparameters (:class:`nnfmu.study.Hyper` fields) that ``nnfmu tune`` starts from where the study's
        tables (:mod:`nnfmu.study.presets`) have none for it (the defaults of its config otherwise).
    search_rank : int, optional
        Place in the architectures that ``nnfmu train --max-minutes`` searches (lowest first), whose trials it may
        average into one model; at the defaults, ``nnfmu train`` trains such a network from two seeds where a core
        is idle. None: not searched, one training.
    data_plan : bool or "budget"
        What ``nnfmu train`` chooses from the data for it where the user left it out (:mod:`nnfmu.training.plan`):
        True: windows, batch, budget and validation tail, and ``--max-minutes`` alone searches; ``"budget"``: the
        same on whole trajectories and without the search (a model whose initial state from ``y0`` holds at a
        record's start only, such as the hybrid's physics state); False: nothing (the TrainConfig defaults).
    linear_path : bool or "own"
        Whether it may sit on a linear path (``linear_order > 0``), identified by ``nnfmu train`` from the data:
        True: the model is wrapped as a correction on the path (:class:`~nnfmu.models.linear_path.LinearPathStepModel`);
        ``"own"``: the model holds the identified linear model itself (it has ``PATH_ARRAYS`` and ``set_path``, as
        the subspace-encoder state-space model, :mod:`nnfmu.ss`); False: never.
    strategies : tuple of str
        The training strategies it takes (the first is the default).
    dtype : str
        The default training dtype.
    counting_config : ``config -> config``, optional
        The config to build on torch's ``meta`` device when counting parameters (one that compiles nothing).
    check_device : ``(config, device) -> None``, optional
        Raise :class:`~nnfmu.errors.ConfigError` if the model cannot train on ``device``.
    """

    name: str
    config_class: Ref
    model_class: Ref
    summary: str = ""
    casadi_step: Ref | None = None
    casadi_init: Ref | None = None
    to_casadi: Ref | None = None
    casadi_model: Ref | None = None
    rollout_cell: Ref | None = None
    training_rollout: Ref | None = None
    options: tuple[Option, ...] = ()
    grid: Mapping[str, tuple] = field(default_factory=dict)
    preset: Mapping[str, Any] = field(default_factory=dict)
    search_rank: int | None = None
    data_plan: bool | str = True
    linear_path: bool | str = True
    strategies: tuple[str, ...] = ("parallel", "series-parallel")
    dtype: str = "float32"
    counting_config: Ref | None = None
    check_device: Ref | None = None

    def __post_init__(self) -> None:
        if not is_c_identifier(self.name):
            raise ConfigError(f"an architecture's name must be a C identifier (ASCII letters, digits, _), "
                              f"got {self.name!r}")
        if self.data_plan not in (True, False, "budget"):
            raise ConfigError(f"architecture {self.name!r}: data_plan must be True, False or 'budget', "
                              f"got {self.data_plan!r}")
        if self.linear_path not in (True, False, "own"):
            raise ConfigError(f"architecture {self.name!r}: linear_path must be True, False or 'own', "
                              f"got {self.linear_path!r}")
        if (self.casadi_step is None) != (self.casadi_init is None):
            raise ConfigError(f"architecture {self.name!r}: give casadi_step and casadi_init together")
        if (self.to_casadi is None) != (self.casadi_model is None):
            raise ConfigError(f"architecture {self.name!r}: give to_casadi and casadi_model together")
        object.__setattr__(self, "options", tuple(self.options))
        object.__setattr__(self, "grid", MappingProxyType({k: tuple(v) for k, v in dict(self.grid).items()}))
        object.__setattr__(self, "preset", MappingProxyType(dict(self.preset)))

    def get(self, attribute: str):
        """The record's ``attribute`` with a lazy reference resolved (None stays None)."""
        value = getattr(self, attribute)
        return None if value is None else resolve(value)

    def references(self) -> dict[str, Ref]:
        """``{where: reference}`` of every class and function the record names (its options' too)."""
        refs = {name: getattr(self, name) for name in _REFERENCES if getattr(self, name) is not None}
        for option in self.options:
            refs.update({f"{option.flag} {name}": getattr(option, name) for name in ("choices", "parse")
                         if isinstance(getattr(option, name), str) or callable(getattr(option, name))})
        return refs


#: The fields of a record that name a class or function.
_REFERENCES = ("config_class", "model_class", "casadi_step", "casadi_init", "to_casadi", "casadi_model",
               "rollout_cell", "training_rollout", "counting_config", "check_device")


def check_references(record: Architecture) -> None:
    """Resolve every reference of ``record``; ConfigError naming the first that does not resolve to a callable."""
    for where, ref in record.references().items():
        try:
            value = resolve(ref)
        except (ImportError, AttributeError) as exc:
            raise ConfigError(f"architecture {record.name!r}: its {where} {ref!r} does not resolve ({exc}); "
                              "fix the reference") from exc
        if not callable(value):
            raise ConfigError(f"architecture {record.name!r}: its {where} {ref!r} is {type(value).__name__}, "
                              "not a class or function")


_RECORDS: dict[str, Architecture] = {}


def register_architecture(record: Architecture) -> Architecture:
    """Make ``record.name`` known. The same record again is a no-op; another under a taken name is an error."""
    if not isinstance(record, Architecture):
        raise ConfigError(f"register_architecture takes an Architecture record, got {type(record).__name__}")
    taken = _RECORDS.get(record.name)
    if taken is not None and taken != record:
        raise ConfigError(f"architecture {record.name!r} is already registered; choose another name")
    _RECORDS[record.name] = record
    return record


_loaded: set[str] = set()


def _plugin_modules() -> list[str]:
    return plugin_modules(ENTRY_POINT_GROUP)


def _ordered() -> tuple[Architecture, ...]:
    """The records registered so far, by name: an order that neither the import order nor the installer changes
    (setuptools writes the entry points sorted by name, not in pyproject.toml's order)."""
    return tuple(sorted(_RECORDS.values(), key=lambda r: r.name))


def load_plugins() -> None:
    """Import every module that the entry points and ``NNFMU_PLUGINS`` name, once each (they register themselves).

    Raises ConfigError naming the modules that cannot be imported, after importing the others (tried once).
    """
    import_once(_plugin_modules(), _loaded, "architecture plugin")


def architecture(arch: str) -> Architecture:
    """The record of ``arch``; :class:`ConfigError` listing the known names otherwise.

    A plugin that cannot be imported fails only the lookup of a name that no other module provides.
    """
    failed = None
    if arch not in _RECORDS:
        try:
            load_plugins()
        except ConfigError as exc:
            failed = exc
    if arch not in _RECORDS:
        raise ConfigError(f"unknown architecture {arch!r}; choose one of {', '.join(r.name for r in _ordered())}, "
                          f"or make its package known (an entry point in the group {ENTRY_POINT_GROUP!r}, or its module in "
                          f"{PLUGINS_ENV})" + ("" if failed is None else f" ({failed})"))
    return _RECORDS[arch]


def is_architecture(arch: str) -> bool:
    """Whether a record of ``arch`` is registered (the plugins loaded first)."""
    try:
        architecture(arch)
    except ConfigError:
        return False
    return True


def records() -> tuple[Architecture, ...]:
    """Every architecture's record, the plugins loaded first, by name."""
    load_plugins()
    return _ordered()


def names(where: Callable[[Architecture], bool] | None = None) -> tuple[str, ...]:
    """The names of the architectures (those whose record satisfies ``where``), in the order of :func:`records`."""
    return tuple(r.name for r in records() if where is None or where(r))


def search_order() -> tuple[str, ...]:
    """The architectures ``nnfmu train --max-minutes`` searches: those with a ``search_rank``, lowest first."""
    return tuple(r.name for r in sorted((r for r in records() if r.search_rank is not None),
                                        key=lambda r: r.search_rank))


def config_class(arch: str) -> type | None:
    """The config class of ``arch`` (None for a name that nothing provides)."""
    try:
        return architecture(arch).get("config_class")
    except ConfigError:
        return None


def model_class(arch: str) -> type:
    """The model class of ``arch``; :class:`ConfigError` listing the known ones otherwise."""
    return architecture(arch).get("model_class")
