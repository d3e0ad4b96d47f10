"""The registries are the only source of names: outside its own folder, no module of nnfmu tests an
architecture's name in a string comparison or writes it into a hand-written list (issue 35).

The names come from the registry itself (every record the entry points register), and the tree is read
as tests/test_import_graph.py reads it, by its syntax: a comparison (``arch == "gru"``, ``arch in ("gru",
"lstm")``) or a tuple, list, set or dict key written with a name, in a module outside the folder of the
architecture's config class (``nnfmu/networks/recurrent/`` for ``"gru"``, ``nnfmu/ss/`` for ``"ss"``).
A function per kind of registry: architectures here; the physics models' half follows the same shape.
"""

from __future__ import annotations

import ast
from pathlib import Path

import nnfmu
from nnfmu.models import architectures

PACKAGE = Path(nnfmu.__file__).parent


def _folder(ref) -> Path:
    """The folder of the package that holds a record's reference (its config class)."""
    module = ref.partition(":")[0] if isinstance(ref, str) else ref.__module__
    return PACKAGE.parent.joinpath(*module.split(".")[:-1])


def _literals(node: ast.AST) -> list[str]:
    """The string constants written in ``node`` itself or in a tuple, list or set literal it is."""
    if isinstance(node, ast.Constant) and isinstance(node.value, str):
        return [node.value]
    if isinstance(node, (ast.Tuple, ast.List, ast.Set)):
        return [e.value for e in node.elts if isinstance(e, ast.Constant) and isinstance(e.value, str)]
    return []


def named_in(source: str, names: set[str]) -> list[tuple[int, str]]:
    """``(line, name)`` of each name of ``names`` that ``source`` compares with or lists by hand."""
    found = []
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Compare):
            written = [s for side in (node.left, *node.comparators) for s in _literals(side)]
        elif isinstance(node, (ast.Tuple, ast.List, ast.Set)):
            written = _literals(node)
        elif isinstance(node, ast.Dict):
            written = [s for key in node.keys if key is not None for s in _literals(key)]
        else:
            continue
        found += [(node.lineno, s) for s in written if s in names]
    return sorted(set(found))  # a tuple compared with is seen as a comparison and as a tuple


def sources() -> dict[Path, str]:
    """Every module of nnfmu and its text."""
    return {path: path.read_text(encoding="utf-8") for path in sorted(PACKAGE.rglob("*.py"))}


def stray_names(names: dict[str, Path], texts: dict[Path, str]) -> list[str]:
    """``file:line: name`` of each name of ``names`` (name -> its own folder) compared or listed outside its folder."""
    stray = []
    for path, text in texts.items():
        own = {name for name, folder in names.items() if folder in path.parents}
        for line, name in named_in(text, set(names) - own):
            stray.append(f"{path.relative_to(PACKAGE.parent)}:{line}: {name!r}")
    return sorted(set(stray))


def architecture_folders() -> dict[str, Path]:
    return {r.name: _folder(r.config_class) for r in architectures.records()}


def test_no_architecture_name_is_compared_or_listed_outside_its_folder():
    folders = architecture_folders()
    assert {"mlp", "rnn", "lstm", "gru", "tcn", "ss"} <= set(folders)  # the registry is read, not this list
    assert folders["gru"] == PACKAGE / "networks" / "recurrent" and folders["ss"] == PACKAGE / "ss"
    assert stray_names(folders, sources()) == [], "read the architecture's record instead (a capability field, names())"


def test_the_scan_finds_a_comparison_and_a_list_added_anywhere():
    """The check can fail: a comparison added to a module outside the folder is found, in every form."""
    names = {"gru", "tcn"}
    assert named_in('if config.arch == "gru":\n    pass\n', names) == [(1, "gru")]
    assert named_in('ok = arch not in ("tcn", "other")\n', names) == [(1, "tcn")]
    assert named_in('KINDS = {"tcn": 0}\nSEARCHED = ["gru"]\n', names) == [(1, "tcn"), (2, "gru")]
    assert named_in('text = "a gru network"\nModelConfig(arch=arch)\n', names) == []
    folders = architecture_folders()
    for module, added in (("training/compiled_window.py", 'if model.config.arch == "tcn":\n    pass\n'),
                          ("study/budgets.py", 'ARCHS = ("mlp", "rnn")\n'),
                          ("networks/tcn/model.py", 'SEEN = arch in ("gru", "tcn")\n')):
        path = PACKAGE / module
        text = path.read_text(encoding="utf-8")
        assert stray_names(folders, {path: text}) == []
        line = text.count("\n") + 1
        found = stray_names(folders, {path: text + added})
        assert found and all(s.startswith(f"nnfmu/{module}:{line}: ") for s in found), found
    # in its own folder the TCN may name itself: only the GRU is stray there
    assert stray_names(folders, {path: text + added}) == [f"nnfmu/networks/tcn/model.py:{line}: 'gru'"]


def test_each_public_name_of_a_package_is_declared_once():
    """models, networks, training, ss and the hybrid write each public name once, as an import (nnfmu._lazy.declared_exports):
    no lazy table or ``__all__`` list beside it, and every name resolves, lazily or not."""
    import importlib

    for package in ("nnfmu.models", "nnfmu.networks", "nnfmu.training", "nnfmu.ss", "nnfmu.hybrid"):
        module = importlib.import_module(package)
        source = Path(module.__file__).read_text(encoding="utf-8")
        assert "_LAZY" not in source and "__all__ = [" not in source, package
        imported = [a.asname or a.name for node in ast.walk(ast.parse(source)) if isinstance(node, ast.ImportFrom)
                    and (node.module or "").startswith("nnfmu.") and not node.module.startswith("nnfmu._")
                    for a in node.names]
        assert sorted(n for n in imported if not n.startswith("_")) == module.__all__, package
        assert all(getattr(module, name) is not None for name in module.__all__), package
    assert {"ModelConfig", "StepModel", "Architecture", "build_model"} <= set(importlib.import_module("nnfmu.models").__all__)
