"""Which config and model class serve each architecture name: a registry other packages fill in.

``nnfmu.models`` registers its five networks. A package built on top of it (``nnfmu.hybrid``,
or a third party) registers its own architecture when it is imported::

    register_architecture("hybrid", config_class=HybridConfig, model_class=HybridStepModel)

so that ``models`` never imports the packages above it. A checkpoint names its architecture
only as a string; when that name is not registered yet, the package that provides it is found
through the entry-point group ``nnfmu.architectures`` (entry name = architecture, value = the
module to import, e.g. ``hybrid = "nnfmu.hybrid"`` in nnfmu's own ``pyproject.toml``).
This module imports neither torch nor the architectures themselves.
"""

from __future__ import annotations

import importlib
from importlib.metadata import entry_points

from nnfmu.errors import ConfigError

ENTRY_POINT_GROUP = "nnfmu.architectures"

_CONFIG_CLASSES: dict[str, type] = {}
_MODEL_CLASSES: dict[str, type] = {}


def register_architecture(arch: str, *, config_class: type | None = None, model_class: type | None = None) -> None:
    """Make ``arch`` known: its config class (``from_dict`` of a stored config) and its model class (``build_model``).

    Registering the same classes again is a no-op; another class under a taken name is an error.
    """
    for table, cls in ((_CONFIG_CLASSES, config_class), (_MODEL_CLASSES, model_class)):
        if cls is None:
            continue
        if table.get(arch, cls) is not cls:
            raise ConfigError(f"architecture {arch!r} is already registered with {table[arch].__name__}; "
                              f"choose another name for {cls.__name__}")
        table[arch] = cls


def _discover(arch: str) -> None:
    """Import the module that the ``nnfmu.architectures`` entry point ``arch`` names (it registers itself)."""
    for ep in entry_points(group=ENTRY_POINT_GROUP):
        if ep.name == arch:
            importlib.import_module(ep.value.split(":")[0])
            return


def _lookup(table: dict[str, type], arch: str, what: str) -> type:
    if arch not in table:
        _discover(arch)
    if arch not in table:
        known = ", ".join(sorted(set(_CONFIG_CLASSES) | set(_MODEL_CLASSES)))
        raise ConfigError(f"unknown architecture {arch!r} (no {what} registered); choose one of {known}, or import "
                          f"the package that provides it (installed packages declare it under the entry-point "
                          f"group {ENTRY_POINT_GROUP!r})")
    return table[arch]


def config_class(arch: str) -> type | None:
    """The config class registered for ``arch`` (None for a name that no package provides)."""
    try:
        return _lookup(_CONFIG_CLASSES, arch, "config class")
    except ConfigError:
        return None


def model_class(arch: str) -> type:
    """The model class registered for ``arch``; :class:`ConfigError` listing the known ones otherwise."""
    return _lookup(_MODEL_CLASSES, arch, "model class")


def registered() -> tuple[str, ...]:
    """The architecture names registered so far."""
    return tuple(sorted(set(_CONFIG_CLASSES) | set(_MODEL_CLASSES)))
