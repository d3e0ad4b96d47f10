"""Names a package re-exports but imports only on first use, so that importing it stays light."""

from __future__ import annotations

import ast
import importlib
from pathlib import Path
from typing import Callable, Mapping


def lazy_exports(package: str, namespace: dict, table: Mapping[str, str]) -> tuple[Callable, Callable]:
    """The module-level ``__getattr__`` and ``__dir__`` of ``package`` for ``table`` (name -> module).

    A name is imported from its module on first access and then cached in ``namespace``
    (the package's ``globals()``), so later lookups cost nothing.
    """

    def __getattr__(name: str):
        if name not in table:
            raise AttributeError(f"module {package!r} has no attribute {name!r}")
        value = getattr(importlib.import_module(table[name]), name)
        namespace[name] = value
        return value

    def __dir__():
        return sorted(set(namespace) | set(table))

    return __getattr__, __dir__


def declared_exports(namespace: dict) -> tuple[Callable, Callable, list[str]]:
    """``__getattr__``, ``__dir__`` and ``__all__`` of a package from its one declaration of its public names.

    The package writes each public name once, as an import: at module level for what it imports at once (e.g.
    the light records), and inside ``if TYPE_CHECKING:`` for what it imports on first use (torch, CasADi)::

        from typing import TYPE_CHECKING

        from nnfmu._lazy import declared_exports
        from nnfmu.models.architectures import Architecture

        if TYPE_CHECKING:
            from nnfmu.models.base import StepModel

        __getattr__, __dir__, __all__ = declared_exports(globals())

    Type checkers and documentation tools read the imports; here the package's source is read for them
    (``namespace["__file__"]``): the ``TYPE_CHECKING`` ones become the lazy table, and every ``from nnfmu...
    import`` name not starting with ``_`` (and not from a private ``nnfmu._`` module) is in ``__all__`` (a module-level ``as other`` exports ``other``; a lazy
    name keeps its own name).
    """
    table: dict[str, str] = {}
    public: list[str] = []
    tree = ast.parse(Path(namespace["__file__"]).read_text(encoding="utf-8"))
    for node in tree.body:
        lazy = isinstance(node, ast.If) and isinstance(node.test, ast.Name) and node.test.id == "TYPE_CHECKING"
        for imp in node.body if lazy else [node]:
            module = imp.module or "" if isinstance(imp, ast.ImportFrom) else ""
            if not module.startswith("nnfmu") or module.startswith("nnfmu._"):  # e.g. this helper itself
                continue
            for alias in imp.names:
                name = alias.asname or alias.name
                if lazy and alias.asname is not None:
                    raise ImportError(f"{namespace['__name__']}: a lazy name is imported under its own name, "
                                      f"not 'as {alias.asname}'")
                if lazy:
                    table[name] = imp.module
                if not name.startswith("_"):
                    public.append(name)
    getattr_, dir_ = lazy_exports(namespace["__name__"], namespace, table)
    return getattr_, dir_, sorted(set(public))
