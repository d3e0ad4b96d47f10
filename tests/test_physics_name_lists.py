"""The physics registry is the only list of physics models: no other module compares with or lists their names.

A physics model's name (``valve``) and its studies' names (``robot``, the arm's measured data) may appear in its
own modules (where its entry's ``build`` and ``generate`` are defined) and anywhere as text; a string comparison
(``system == "valve"``, ``system in ("valve", "arm")``, a ``match`` case), a hand-written list, tuple or set, or
a dict keyed by the names, anywhere else in ``nnfmu/``, means that adding a model needs an edit there. The tree is
read with :mod:`ast`, as tests/test_import_graph.py reads the imports. The architecture names have their own test
(tests/test_name_lists.py).
"""

from __future__ import annotations

import ast
from pathlib import Path

import nnfmu
from nnfmu.physics import physics_entry, physics_names, study_names

PACKAGE = Path(nnfmu.__file__).parent

#: (file, assigned name) -> why a table keyed by the names is data there, not a second registry.
ALLOWED = {
    ("study/budgets.py", "_MEASURED"): "the measured hyperparameters of a (system, architecture) pair; a study "
                                       "without a table starts every architecture at its record's preset",
    ("study/budgets.py", "_DEMO"): "nnfmu demo's budget, which is the valve's by definition (nnfmu.study.demo)",
}


def _own_modules() -> dict[str, set[str]]:
    """``{name: {files}}``: where each model's entry (and so its studies) is defined, relative to nnfmu/."""
    own: dict[str, set[str]] = {}
    for name in physics_names():
        entry = physics_entry(name)
        files = {_file(f.__module__) for f in (entry.build, entry.generate) if f is not None}
        for n in (name, *(s.name for s in entry.studies)):
            own.setdefault(n, set()).update(files)
    return own


def _file(module: str) -> str:
    parts = module.split(".")[1:]
    return "/".join(parts) + ".py"


def findings(source: str, names: set[str], skip: set[str] = frozenset()) -> list[tuple[int, str]]:
    """``[(line, name)]`` of each comparison with, or hand-written list of, ``names`` in ``source``; the values
    of top-level assignments to ``skip`` are not read."""
    found: list[tuple[int, str]] = []

    def named(node) -> str | None:
        return node.value if isinstance(node, ast.Constant) and node.value in names else None

    def literal(node) -> list[str]:
        if isinstance(node, (ast.List, ast.Tuple, ast.Set)):
            return [n for n in map(named, node.elts) if n]
        if isinstance(node, ast.Dict):
            return [n for n in map(named, filter(None, node.keys)) if n]
        return []

    tree = ast.parse(source)
    skipped = {id(n.value) for n in tree.body if isinstance(n, ast.Assign)
               and any(getattr(t, "id", None) in skip for t in n.targets)}
    stack = [n for n in ast.iter_child_nodes(tree)]
    while stack:
        node = stack.pop()
        if id(node) in skipped:
            continue
        if isinstance(node, ast.Compare):
            for side in (node.left, *node.comparators):
                found += [(node.lineno, n) for n in ([named(side)] if named(side) else literal(side))]
        elif isinstance(node, ast.MatchValue) and named(node.value):
            found.append((node.lineno, named(node.value)))
        else:
            found += [(node.lineno, n) for n in literal(node)]
        stack.extend(ast.iter_child_nodes(node))
    return sorted(set(found))


def test_no_physics_name_is_compared_or_listed_outside_its_own_modules():
    own = _own_modules()
    names = set(own)
    assert {"valve", "arm", "slider", "robot"} <= names  # the test reads the registry, not a list of its own
    bad = []
    for path in sorted(PACKAGE.rglob("*.py")):
        rel = path.relative_to(PACKAGE).as_posix()
        skip = {var for (file, var) in ALLOWED if file == rel}
        for line, name in findings(path.read_text(encoding="utf-8"), names, skip):
            if rel not in own[name]:
                bad.append(f"nnfmu/{rel}:{line}: {name!r}")
    assert bad == [], "read the physics registry (nnfmu.physics.physics_entry, study_preset) instead:\n" + \
        "\n".join(bad)


def test_the_allowed_tables_exist():
    """An exception that no longer matches anything must go, so that the list stays short and true."""
    for file, var in ALLOWED:
        tree = ast.parse((PACKAGE / file).read_text(encoding="utf-8"))
        assert any(isinstance(n, ast.Assign) and any(getattr(t, "id", None) == var for t in n.targets)
                   for n in tree.body), (file, var)


def test_the_check_sees_each_kind_of_name_list():
    names = {"valve", "arm"}
    cases = {
        'if system == "valve":\n    pass\n': [(1, "valve")],
        'ok = "arm" != kind\n': [(1, "arm")],
        'ok = system in ("valve", "arm")\n': [(1, "arm"), (1, "valve")],
        'SYSTEMS = ["valve", "other"]\n': [(1, "valve")],
        'TITLES = {"arm": "Robot arm"}\n': [(1, "arm")],
        'match system:\n    case "valve":\n        pass\n': [(2, "valve")],
        'print("the valve and the arm")\nf(system="valve")\n': [],  # text and arguments are not lists
    }
    for source, expected in cases.items():
        assert findings(source, names) == expected, source
    assert findings('T = {"valve": 1}\n', names, skip={"T"}) == []


def test_the_check_fails_when_a_comparison_is_added(tmp_path):
    """The tree as it is passes; the same tree with one comparison added to a study module does not."""
    source = (PACKAGE / "study" / "results.py").read_text(encoding="utf-8")
    assert findings(source, set(study_names())) == []
    added = source + '\n\ndef _is_valve(study):\n    return study.system == "valve"\n'
    assert [name for _, name in findings(added, set(study_names()))] == ["valve"]
