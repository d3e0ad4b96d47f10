"""The import graph of nnfmu/: no circles, and the layers of docs/design.md point one way.

Every ``import`` and ``from ... import`` of every module counts, at module level and inside
functions alike (a function-level import only delays a circle, it does not remove it), and so
do the names a package re-exports lazily (``_LAZY`` tables, :mod:`nnfmu._lazy`). The root
package ``nnfmu/__init__.py`` (the public facade) and ``__main__`` entry shims (``python -m
nnfmu.export``) sit above everything and are left out. Imports built from strings at run time
(``importlib.import_module``) are not seen: nnfmu uses them only for its own CLI commands, the
physics models of ``nnfmu physics-fmu`` and the architecture entry points.
"""

from __future__ import annotations

import ast
from collections import defaultdict
from pathlib import Path

import nnfmu

PACKAGE = Path(nnfmu.__file__).parent

#: Lowest first: a unit may import its own layer (without circles) and the layers below it, never one above.
#: Top-level modules and subpackages are units; a new one must be placed here.
LAYERS = (
    ("ground", {"errors", "atomic", "cbuild", "identifiers", "_lazy", "__version__", "tempdirs", "window_names", "plugins",
                "system", "signals", "metrics", "valid_range", "protocols", "limits", "progress"}),
    ("data", {"data"}),
    ("physics, linear and co-simulation", {"physics", "linear", "cosim", "plots", "greybox"}),
    ("models", {"models"}),
    ("training", {"training"}),
    ("export", {"export"}),
    ("networks", {"networks"}),
    ("hybrid", {"hybrid"}),
    ("node", {"node"}),
    ("ss", {"ss"}),
    ("study", {"study"}),
    ("cli", {"cli"}),
)
LAYER = {unit: i for i, (_, units) in enumerate(LAYERS) for unit in units}


def _modules() -> dict[str, Path]:
    found = {}
    for path in PACKAGE.rglob("*.py"):
        parts = ("nnfmu", *path.relative_to(PACKAGE).with_suffix("").parts)
        if parts[-1] == "__main__" or parts == ("nnfmu", "__init__"):
            continue
        found[".".join(parts[:-1] if parts[-1] == "__init__" else parts)] = path
    return found


def _imported(module: str, path: Path) -> dict[str, int]:
    """``{dotted name: line}`` of everything ``module`` imports (the name may end in an attribute)."""
    package = module if path.name == "__init__.py" else module.rpartition(".")[0]
    names: dict[str, int] = {}
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Import):
            names.update({a.name: node.lineno for a in node.names})
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                up = package.split(".")[: len(package.split(".")) - node.level + 1]
                base = ".".join([*up, *([base] if base else [])])
            names.update({f"{base}.{a.name}": node.lineno for a in node.names})
        elif isinstance(node, ast.Assign) and any(getattr(t, "id", None) == "_LAZY" for t in node.targets):
            names.update({v.value: node.lineno for v in ast.walk(node.value)
                          if isinstance(v, ast.Constant) and isinstance(v.value, str) and "." in v.value})
    return {n: line for n, line in names.items() if n.startswith("nnfmu.")}


def _graph() -> dict[str, dict[str, str]]:
    """``{module: {imported module: "file:line"}}`` between modules of nnfmu; a module's own packages left out
    (importing ``nnfmu.data.tables`` runs ``nnfmu/data/__init__.py`` first, which is not an arrow back)."""
    modules = _modules()
    graph: dict[str, dict[str, str]] = defaultdict(dict)
    for module, path in modules.items():
        for name, line in _imported(module, path).items():
            while name not in modules and "." in name:
                name = name.rpartition(".")[0]
            if name in modules and name != module and not module.startswith(name + "."):
                graph[module].setdefault(name, f"{path.relative_to(PACKAGE.parent)}:{line}")
    return graph


def _unit(module: str) -> str:
    return module.split(".")[1]


def _cycles(graph: dict[str, dict]) -> list[list[str]]:
    """The strongly connected components with more than one node (Tarjan)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    found: list[list[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        for w in graph.get(v, {}):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                component.append(w)
                if w == v:
                    break
            if len(component) > 1:
                found.append(sorted(component))

    for v in list(graph):
        if v not in index:
            visit(v)
    return found


def test_every_unit_has_a_layer():
    units = {_unit(m) for m in _modules()}
    assert units - set(LAYER) == set(), "place each new module or subpackage in LAYERS (and docs/design.md)"


def test_no_arrow_from_a_lower_layer_to_a_higher_one():
    back = [f"{where}: {_unit(a)} ({LAYERS[LAYER[_unit(a)]][0]}) imports {b} ({LAYERS[LAYER[_unit(b)]][0]})"
            for a, targets in _graph().items() for b, where in targets.items()
            if LAYER.get(_unit(b), -1) > LAYER.get(_unit(a), len(LAYERS))]
    assert back == []


def test_no_circle_between_units():
    units: dict[str, dict[str, str]] = defaultdict(dict)
    for a, targets in _graph().items():
        for b, where in targets.items():
            if _unit(a) != _unit(b):
                units[_unit(a)].setdefault(_unit(b), f"{a} -> {b} ({where})")
    circles = _cycles(units)
    assert circles == [], [[units[a][b] for a in c for b in c if b in units[a]] for c in circles]


def test_no_circle_between_modules():
    graph = _graph()
    circles = _cycles(graph)
    assert circles == [], [[f"{a} -> {b} ({graph[a][b]})" for a in c for b in c if b in graph[a]] for c in circles]


def test_the_checks_see_function_level_imports_and_lazy_tables():
    """The scan is not blind: the lazy table of nnfmu.export and a function-level import are arrows."""
    graph = _graph()
    assert "nnfmu.export.torch_to_casadi" in graph["nnfmu.export"]  # _LAZY = {"to_casadi": "nnfmu.export.torch_to_casadi"}
    assert "nnfmu.models.base" in graph["nnfmu.study.parallel"]  # inside run_in_place
    assert _cycles({"a": {"b": ""}, "b": {"c": ""}, "c": {"a": ""}, "d": {"a": ""}}) == [["a", "b", "c"]]
