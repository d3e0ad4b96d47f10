"""Which physics models the toolkit knows, by one name: the built-in ones and the user's own.

A *spec* names a physics model: a registered name (``"valve"``, ``"arm"``, ``"slider"``), a
user's model file ``path/to/file.py:NAME`` (loading it runs the file's code; :mod:`nnfmu.physics.model_file`),
a ``.json`` physics document or grey-box fit result, or a :class:`PhysicsSystem` itself. Each built-in
model registers itself in its own module
(``register_physics(PhysicsEntry("valve", valve_system, ...))``), so adding a model is one
module and one registration. Every command and API that takes a physics model resolves it
here (:func:`resolve_physics`); ``--physics`` choices come from :func:`physics_names`.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from typing import Callable

from nnfmu.errors import ConfigError
from nnfmu.physics.base import PhysicsSystem

__all__ = ["PhysicsEntry", "register_physics", "physics_names", "physics_entry", "resolve_physics"]


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
    """

    name: str
    build: Callable[[], PhysicsSystem]
    corrected_states: tuple[str, ...] | None = None
    correction_time: float | None = None


_ENTRIES: dict[str, PhysicsEntry] = {}


def register_physics(entry: PhysicsEntry) -> None:
    """Make ``entry.name`` known. The same entry again is a no-op; another under a taken name is an error."""
    taken = _ENTRIES.get(entry.name)
    if taken is not None and taken != entry:
        raise ConfigError(f"physics model {entry.name!r} is already registered; choose another name")
    _ENTRIES[entry.name] = entry


def _builtins() -> None:
    import nnfmu.physics  # noqa: F401  (the built-in models register themselves on import)


def physics_names() -> tuple[str, ...]:
    """The registered physics models' names, sorted."""
    _builtins()
    return tuple(sorted(_ENTRIES))


def physics_entry(name: str) -> PhysicsEntry:
    """The registered entry called ``name`` (ConfigError naming the choices when there is none)."""
    _builtins()
    if name not in _ENTRIES:
        raise ConfigError(f"unknown physics model {name!r}; choose one of {', '.join(sorted(_ENTRIES))}")
    return _ENTRIES[name]


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
