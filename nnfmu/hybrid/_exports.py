"""The hybrid package's lazy public names, declared once: by the imports of its ``if TYPE_CHECKING:`` block.

Tools (mkdocstrings, type checkers) read those imports; at run time :func:`declared_exports` reads the same
block from the package's source, so the names are imported on first use (:func:`nnfmu._lazy.lazy_exports`)
and ``__all__`` lists them, without a second or third list to keep in step.
"""

from __future__ import annotations

import ast
from pathlib import Path


def declared_exports(init_file: str) -> dict[str, str]:
    """``{name: module}`` of every ``from MODULE import NAME`` inside ``if TYPE_CHECKING:`` in ``init_file``."""
    tree = ast.parse(Path(init_file).read_text(encoding="utf-8"))
    found: dict[str, str] = {}
    for node in tree.body:
        if isinstance(node, ast.If) and getattr(node.test, "id", None) == "TYPE_CHECKING":
            for stmt in node.body:
                if isinstance(stmt, ast.ImportFrom) and stmt.module and not stmt.level:
                    found.update({alias.asname or alias.name: stmt.module for alias in stmt.names})
    return found
