"""The C core's calls go one way, as in the FMI Reference FMUs: the FMI wrappers call the core, the lifecycle
(nnfmu_core.c) calls Model Exchange, Model Exchange calls the step code, and every file logs through
nnfmu_log.c, which calls none of them. A circle between the template files would mean that the framework's
layers lean on each other both ways (the step code calling back into the lifecycle, say).

Read from the sources as tests/test_import_graph.py reads the Python imports: a file depends on another when it
calls an ``nnfmu_*`` function that the other defines.
"""

from __future__ import annotations

import re
from importlib import resources

TEMPLATES = resources.files("nnfmu.export") / "templates"
_DEFINITION = re.compile(r"^[A-Za-z_][\w \*]*?\b(nnfmu_\w+)\(", re.M)  # at column 0: a definition, not a call
_CALL = re.compile(r"\b(nnfmu_\w+)\(")


def _graph(sources: dict[str, str]) -> dict[str, set[str]]:
    """``{file: {files whose functions it calls}}``."""
    defined = {}
    for name, text in sources.items():
        body = re.sub(r"/\*.*?\*/", "", text, flags=re.S)
        for line in body.splitlines():
            m = _DEFINITION.match(line)
            if m and not line.rstrip().endswith(";") and not line.startswith(("static", "#", "typedef")):
                defined[m[1]] = name
    graph = {}
    for name, text in sources.items():
        body = re.sub(r"/\*.*?\*/", "", text, flags=re.S)
        graph[name] = {defined[f] for f in _CALL.findall(body) if f in defined and defined[f] != name}
    return graph


def _circles(graph: dict[str, set[str]]) -> list[list[str]]:
    found, state = [], {}

    def visit(node: str, path: list[str]) -> None:
        state[node] = "open"
        for nxt in sorted(graph.get(node, ())):
            if state.get(nxt) == "open":
                found.append(path[path.index(nxt):] + [nxt])
            elif nxt not in state:
                visit(nxt, path + [nxt])
        state[node] = "done"

    for node in sorted(graph):
        if node not in state:
            visit(node, [node])
    return found


def _sources() -> dict[str, str]:
    return {f.name: f.read_text(encoding="utf-8") for f in TEMPLATES.iterdir() if f.name.endswith(".c")}


def test_the_c_core_has_no_circle():
    graph = _graph(_sources())
    assert graph["nnfmu_core.c"] >= {"nnfmu_me.c", "nnfmu_log.c"}  # the reader sees the calls it must see
    assert _circles(graph) == []


def test_the_layers_point_down():
    graph = _graph(_sources())
    assert graph["nnfmu_log.c"] == set()  # the bottom: logging and the mode checks
    for low in ("nnfmu_step.c", "nnfmu_me.c", "nnfmu_variables.c", "nnfmu_state.c"):
        assert "nnfmu_core.c" not in graph[low], low  # no file below the lifecycle calls back into it
    wrappers = {n for n in graph if n.startswith(("nnfmu_fmi2", "nnfmu_fmi3"))}
    assert all(w not in deps for n, deps in graph.items() for w in wrappers if not n.startswith("nnfmu_fmi"))


def test_the_reader_finds_a_circle_when_one_is_added():
    sources = _sources()
    sources["nnfmu_step.c"] += "\nstatic void back(nnfmu_instance *inst) { nnfmu_reset(inst); }\n"
    assert ["nnfmu_core.c", "nnfmu_me.c", "nnfmu_step.c", "nnfmu_core.c"] in _circles(_graph(sources))
