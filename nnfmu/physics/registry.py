"""Which physics models the toolkit knows, by one name: the built-in ones and the user's own.

A *spec* names a physics model: a registered name (:func:`physics_names`), a
user's model file ``path/to/file.py:NAME`` (loading it runs the file's code; :mod:`nnfmu.physics.model_file`),
a ``.json`` physics document or grey-box fit result, or a :class:`PhysicsSystem` itself. Each built-in
model registers itself in its own module (``register_physics(PhysicsEntry(NAME, build, ...))``, in
``generate_<name>.py`` where the model has its own data generator), so adding a model is one module and
one registration. Every command and API that takes a physics model resolves it here
(:func:`resolve_physics`); ``--physics`` choices come from :func:`physics_names`. An entry also carries
what ``nnfmu generate`` (its generator and sizes) and ``nnfmu reproduce`` (its :class:`StudyPreset` records)
need, so that no other module lists the models by name.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Any, Callable, Mapping

from nnfmu.errors import ConfigError
from nnfmu.plugins import import_once, plugin_modules
from nnfmu.physics.base import PhysicsSystem

__all__ = ["PhysicsEntry", "StudyPreset", "register_physics", "physics_names", "physics_entry", "resolve_physics",
           "study_names", "study_preset"]

#: The sizes of a model without a generator of its own (:data:`nnfmu.physics.generate_model.MODEL_SIZES`).
MODEL_SIZES = ("standard", "small")


@dataclass(frozen=True, kw_only=True)
class StudyPreset:
    """How ``nnfmu reproduce NAME`` studies data of one physics model (:mod:`nnfmu.study`).

    Attributes
    ----------
    name : str
        The study's name (``nnfmu reproduce NAME``): the entry's own name for its generated data, another
        (``robot``) for measured data that the entry's model is compared with.
    title : str
        The heading of ``results.md``, e.g. ``"Pneumatic valve (generated data)"``.
    data_sizes : (str, str) or None
        The generator's sizes of the ``quick``/``paper`` budgets and of ``smoke``; None: measured data the
        user gives (``--data``), of which ``smoke`` keeps 6 training records.
    data_kind : str, optional
        The dataset source's ``kind`` that marks this study's measured data (``"robot-benchmark"``).
    noise : float
        Measurement noise added to generated outputs in every budget, as a fraction of each output's
        training standard deviation.
    linear_quick, linear_paper : mapping
        Options of :func:`nnfmu.linear.identify_linear` in the ``quick`` and ``paper`` budgets.
    quick_epochs, quick_patience, quick_seeds, paper_seeds : int
        Training length of ``quick``, and the seeds of ``quick`` and ``paper``.
    paper_tune : bool
        Whether ``paper`` grid-searches the hyperparameters (False: it keeps the preset recipe).
    physics_label : str
        The physics row's label in the results.
    note : str
        The results' note on the physics row; ``{noise_floor}`` becomes " up to the measurement noise" when
        the data carry added noise, else nothing.
    whole_record : bool
        The figures show the whole first test record (True) or one representative trajectory.
    """

    name: str
    title: str
    data_sizes: tuple[str, str] | None
    data_kind: str | None = None
    noise: float = 0.0
    linear_quick: Mapping[str, Any] = field(default_factory=dict)
    linear_paper: Mapping[str, Any] = field(default_factory=dict)
    quick_epochs: int = 40
    quick_patience: int = 10
    quick_seeds: int = 1
    paper_seeds: int = 1
    paper_tune: bool = True
    physics_label: str = ""
    note: str = ""
    whole_record: bool = False

    def __post_init__(self) -> None:
        try:
            self.note.format(noise_floor="")
        except (KeyError, IndexError, ValueError) as exc:
            raise ConfigError(f"study {self.name!r}: its note may hold {{noise_floor}} and no other braces "
                              f"({exc!r}); write other braces doubled, {{{{ and }}}}") from None
        for name in ("linear_quick", "linear_paper"):
            object.__setattr__(self, name, MappingProxyType(dict(getattr(self, name))))


@dataclass(frozen=True)
class PhysicsEntry:
    """One registered physics model.

    Attributes
    ----------
    name : str
        The name commands take (``--physics NAME``).
    build : callable
        ``build() -> PhysicsSystem`` at the nominal parameters.
    corrected_states : tuple of str, optional
        States whose derivative a hybrid corrects by default (None: every state but the kinematic identities,
        :func:`nnfmu.hybrid.parameters.kinematic_states`).
    correction_time : float, optional
        Seconds; a hybrid's default scale of its derivative correction (None: ten sample times,
        :data:`nnfmu.hybrid.config.DEFAULT_CORRECTION_SAMPLES`).
    generate : callable, optional
        ``generate(*, size, seed, progress, partial_dir) -> Dataset``: the model's own data generator
        (``nnfmu generate NAME``); None: the toolkit's excitation signals within the inputs' ranges
        (:func:`nnfmu.physics.generate_model_dataset`).
    sizes : tuple of str
        The generator's dataset sizes, the default (full) one first.
    title : str
        What the model is, in a few words (``"Pneumatic valve"``); the build's ``name`` when empty.
    studies : tuple of StudyPreset
        The studies ``nnfmu reproduce`` runs on this model's data (none: the model is not studied).
    """

    name: str
    build: Callable[[], PhysicsSystem]
    corrected_states: tuple[str, ...] | None = None
    correction_time: float | None = None
    generate: Callable[..., Any] | None = field(default=None, kw_only=True)
    sizes: tuple[str, ...] = field(default=MODEL_SIZES, kw_only=True)
    title: str = field(default="", kw_only=True)
    studies: tuple[StudyPreset, ...] = field(default=(), kw_only=True)

    def __post_init__(self) -> None:
        if not self.sizes:
            raise ConfigError(f"physics model {self.name!r}: sizes must name at least one dataset size")
        if self.generate is None and not set(self.sizes) <= set(MODEL_SIZES):
            raise ConfigError(f"physics model {self.name!r}: without a generator of its own its sizes are "
                              f"{', '.join(MODEL_SIZES)}, got {self.sizes}; give generate= or those sizes")
        for study in self.studies:
            if study.data_sizes is not None and not set(study.data_sizes) <= set(self.sizes):
                raise ConfigError(f"physics model {self.name!r}: its study {study.name!r} asks for data sizes "
                                  f"{study.data_sizes}, but the model has {self.sizes}; choose among those")


_ENTRIES: dict[str, PhysicsEntry] = {}


def register_physics(entry: PhysicsEntry) -> None:
    """Make ``entry.name`` known. The same entry again is a no-op; another under a taken name is an error."""
    taken = _ENTRIES.get(entry.name)
    if taken is not None and taken != entry:
        raise ConfigError(f"physics model {entry.name!r} is already registered; choose another name")
    studied = {s.name: e.name for e in _ENTRIES.values() if e.name != entry.name for s in e.studies}
    clash = [s.name for s in entry.studies if s.name in studied]
    if clash:
        raise ConfigError(f"physics model {entry.name!r}: the study {clash[0]!r} is already the study of "
                          f"{studied[clash[0]]!r}; choose another study name")
    _ENTRIES[entry.name] = entry


#: Entry-point group of installed packages that register physics models (``[project.entry-points]``).
ENTRY_POINT_GROUP = "nnfmu.physics"
#: The plug-in modules imported so far (:data:`nnfmu.plugins.PLUGINS_ENV` names models and architectures alike, so
#: that one plug-in module can register both).
_loaded: set[str] = set()


def _plugin_modules() -> list[str]:
    return plugin_modules(ENTRY_POINT_GROUP)


def _builtins() -> None:
    import nnfmu.physics  # noqa: F401  (the built-in models register themselves on import)


def _plugins() -> None:
    """Import every plug-in module not imported yet (each tried once; they register themselves).
    ConfigError names the plug-ins that cannot be imported."""
    import_once(_plugin_modules(), _loaded, "plug-in")


def physics_names(*, plugins: bool = True) -> tuple[str, ...]:
    """The registered physics models' names, sorted; ``plugins=False``: without importing the plug-ins first."""
    _builtins()
    if plugins:
        _plugins()
    return tuple(sorted(_ENTRIES))


def physics_entry(name: str) -> PhysicsEntry:
    """The registered entry called ``name`` (the plug-ins imported first when it is unknown; ConfigError naming
    the choices when there is none)."""
    _builtins()
    if name not in _ENTRIES:
        _plugins()
    if name not in _ENTRIES:
        raise ConfigError(f"unknown physics model {name!r}; choose one of {', '.join(sorted(_ENTRIES))}")
    return _ENTRIES[name]


def study_names(*, plugins: bool = True) -> tuple[str, ...]:
    """The names ``nnfmu reproduce`` takes: every registered entry's studies, sorted; ``plugins=False``: without
    importing the plug-ins first."""
    _builtins()
    if plugins:
        _plugins()
    return tuple(sorted(s.name for e in _ENTRIES.values() for s in e.studies))


def _find_study(name: str) -> tuple[PhysicsEntry, StudyPreset] | None:
    return next(((e, s) for e in _ENTRIES.values() for s in e.studies if s.name == name), None)


def study_preset(name: str) -> tuple[PhysicsEntry, StudyPreset]:
    """The entry whose model a study ``name`` compares with, and the study's preset (the plug-ins imported first
    when it is unknown; ConfigError listing the choices when there is none)."""
    _builtins()
    found = _find_study(name)
    if found is None:
        _plugins()
        found = _find_study(name)
    if found is None:
        raise ConfigError(f"unknown system {name!r}; choose one of {', '.join(study_names(plugins=False))}")
    return found


def resolve_physics(spec: str | PhysicsSystem) -> PhysicsSystem:
    """The :class:`PhysicsSystem` a spec names.

    ``spec``: the system itself; a registered name; ``path/to/file.py:NAME`` (runs the file, calls
    ``NAME()``; ``file.py`` alone when it defines one model); or ``path/to/file.json`` (a physics document,
    or a grey-box fit result holding one under ``"physics"``). Errors name the file and the fix.
    """
    if isinstance(spec, PhysicsSystem):
        return spec
    from nnfmu.physics.model_file import is_file_spec, model_from_file, model_from_json, split_spec

    spec = os.fspath(spec) if isinstance(spec, os.PathLike) else str(spec)
    if is_file_spec(spec):
        path, name = split_spec(spec)
        return model_from_json(path) if path.suffix.lower() == ".json" else model_from_file(path, name)
    try:
        return physics_entry(spec).build()
    except ConfigError as exc:
        raise ConfigError(f"{exc}, or give a model file path/to/file.py:NAME or a .json physics document") from None
