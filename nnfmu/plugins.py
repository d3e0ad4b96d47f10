"""Plug-in modules, imported once each: what the architecture and the physics registries share.

A plug-in is a module that registers itself on import. Each registry names its modules by an entry-point group
(``nnfmu.architectures``, ``nnfmu.physics``) and, for both, by :data:`PLUGINS_ENV` (modules separated by commas or
the path separator).
"""

from __future__ import annotations

import importlib
import os

from nnfmu.errors import ConfigError

#: The environment variable that names plug-in modules besides the installed entry points.
PLUGINS_ENV = "NNFMU_PLUGINS"


def plugin_modules(group: str) -> list[str]:
    """The modules the installed entry points of ``group`` name, then those of :data:`PLUGINS_ENV`."""
    from importlib.metadata import entry_points

    listed = [m.strip() for m in os.environ.get(PLUGINS_ENV, "").replace(os.pathsep, ",").split(",")]
    return [ep.value.split(":")[0] for ep in entry_points(group=group)] + [m for m in listed if m]


def import_once(modules, loaded: set, what: str) -> None:
    """Import each of ``modules`` not in ``loaded`` (added to it, so each is tried once; it registers itself).

    Raises ConfigError naming the ``what`` (e.g. "architecture plugin") modules that cannot be imported, after
    importing the others.
    """
    failed = []
    for module in modules:
        if module in loaded:
            continue
        loaded.add(module)
        try:
            importlib.import_module(module)
        except ImportError as exc:
            failed.append(f"{module!r} ({exc})")
    if failed:
        raise ConfigError(f"cannot import the {what} {', '.join(failed)}; install it, put its folder on PYTHONPATH, "
                          f"or drop it from {PLUGINS_ENV}")
