"""The one C build service (nnfmu.cbuild): one function runs the compiler, and every compiled path honours $CC."""

from __future__ import annotations

import ast
import os
import shutil
import stat
import warnings
from pathlib import Path

import casadi as ca
import numpy as np
import pytest
import torch

import nnfmu
from nnfmu import cbuild
from nnfmu.errors import FmuBuildError

PACKAGE = Path(nnfmu.__file__).parent
#: Modules that start processes other than the C compiler, with what they start.
OTHER_PROCESSES = {"training/seed_runs.py": "nnfmu train, one process per seed or refit",
                   "study/trial_pool.py": "nnfmu train --max-minutes, one worker process per core"}


def _process_calls(tree: ast.AST) -> list[int]:
    """Lines that call subprocess.* or os.system/os.exec*/os.spawn*/os.popen."""
    lines = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute):
            owner = node.func.value
            if isinstance(owner, ast.Name) and (owner.id == "subprocess" or (
                    owner.id == "os" and node.func.attr.startswith(("system", "exec", "spawn", "popen")))):
                lines.append(node.lineno)
        if isinstance(node, ast.ImportFrom) and node.module == "subprocess":
            lines.append(node.lineno)
    return lines


def test_only_cbuild_starts_the_c_compiler():
    starts = {}
    for path in PACKAGE.rglob("*.py"):
        lines = _process_calls(ast.parse(path.read_text(encoding="utf-8")))
        if lines:
            starts[path.relative_to(PACKAGE).as_posix()] = lines
    assert set(starts) == {"cbuild.py", *OTHER_PROCESSES}, starts
    tree = ast.parse((PACKAGE / "cbuild.py").read_text(encoding="utf-8"))
    starting = {f.name for f in ast.walk(tree) if isinstance(f, ast.FunctionDef) and _process_calls(f)}
    assert starting == {"_run"}
    for module in OTHER_PROCESSES:
        assert "compiler" not in (PACKAGE / module).read_text(encoding="utf-8").lower()


def test_a_compiler_is_a_command_with_arguments(monkeypatch):
    monkeypatch.setenv("CC", "env gcc")
    assert cbuild.compiler_argv() == (shutil.which("env"), "gcc")
    assert cbuild.compiler_argv("env  'g cc'") == (shutil.which("env"), "g cc")
    assert cbuild.compiler_argv([shutil.which("env"), "cc"]) == (shutil.which("env"), "cc")
    monkeypatch.setenv("CC", "/nowhere/cc gcc")
    with pytest.raises(FmuBuildError, match=r"no C compiler found: looked for '/nowhere/cc gcc' \(\$CC\)"):
        cbuild.compiler_argv()


def test_a_failure_is_one_line_with_the_first_error_and_the_output_attached(tmp_path):
    broken = tmp_path / "broken.c"
    broken.write_text("int f(void) { return 1 }\nint g(void) { return h(); }\n")
    with pytest.raises(FmuBuildError, match=r"^compiling broken failed: \S+ exited with status \d+: .*error") as info:
        cbuild.run_compiler(["-c", str(broken), "-o", str(tmp_path / "b.o")], what="compiling broken")
    assert "\n" not in str(info.value) and "broken.c" in info.value.stderr


def test_a_hung_compiler_is_stopped_with_its_children(tmp_path):
    # answers the GCC question at once, then hangs in a child that keeps the output pipes open
    hang = _script(tmp_path / "hang.sh", 'if [ "$1" = -dM ]; then exit 1; fi\nsleep 30\n')
    with pytest.raises(FmuBuildError, match=r"did not finish within 0.5 s"):
        cbuild.run_compiler(["-c", "x.c"], what="compiling x", compiler=str(hang), timeout_s=0.5)


def _script(path: Path, body: str) -> Path:
    path.write_text("#!/bin/sh\n" + body)
    path.chmod(path.stat().st_mode | stat.S_IXUSR)
    return path


def _compiled_paths(tmp_path: Path) -> dict[str, object]:
    """Build each compiled path once, in a fresh cache; return what each built."""
    from nnfmu.export.fmu import build_fmu
    from nnfmu.hybrid.compiled_torch import CompiledFunction
    from nnfmu.physics.compiled import compile_function
    from nnfmu.system import CasadiModel, SystemSpec
    from nnfmu.training import rollout_library

    x, u = ca.SX.sym("x"), ca.SX.sym("u")
    step = ca.Function("cbuild_step", [x, u], [ca.tanh(x) + u, x], ["x", "u"], ["x_next", "y_next"])
    init = ca.Function("init", [x, u], [x], ["y0", "u0"], ["x0"])
    model = CasadiModel(init, step, SystemSpec("cbuild", 1.0, ["u"], ["y"]))
    return {
        "fmu": build_fmu(model, tmp_path / "m.fmu"),
        "physics": compile_function(step),
        "rollout": rollout_library.library(torch.float64),
        "hybrid": CompiledFunction(step),
    }


def _check_built(built: dict[str, object]) -> None:
    assert built["fmu"].is_file()
    assert built["physics"].is_a("External")
    assert np.allclose(np.asarray(built["physics"](0.5, 0.25)[0]), np.tanh(0.5) + 0.25, rtol=1e-14)
    assert built["rollout"].nnfmu_rollout_forward is not None
    (y, _) = built["hybrid"](torch.tensor([[0.5]], dtype=torch.float64), torch.tensor([[0.25]], dtype=torch.float64))
    assert torch.allclose(y, torch.tensor([[np.tanh(0.5) + 0.25]], dtype=torch.float64))


def test_every_compiled_path_runs_the_compiler_of_cc_with_its_argument(tmp_path, monkeypatch):
    log = tmp_path / "calls.log"
    wrap = _script(tmp_path / "wrap.sh", f'echo "$1" >> "{log}"\nshift\nexec "$@"\n')
    monkeypatch.setenv("CC", f"{wrap} marker gcc")
    monkeypatch.setenv("NNFMU_CACHE_DIR", str(tmp_path / "cache"))
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)  # no path falls back to running uncompiled
        built = _compiled_paths(tmp_path)
    _check_built(built)
    calls = log.read_text().split()
    assert set(calls) == {"marker"} and len(calls) >= 4
    libraries = sorted(p.name.split("_")[0] for p in (tmp_path / "cache" / "compiled").iterdir())
    assert libraries == ["cbuild", "rollout", "torch"]  # and no temporary folder left behind


@pytest.mark.skipif(shutil.which("ccache") is None, reason="ccache is not installed")
def test_cc_ccache_gcc_builds_every_compiled_path(tmp_path, monkeypatch):
    monkeypatch.setenv("CC", "ccache gcc")
    monkeypatch.setenv("CCACHE_DIR", str(tmp_path / "ccache"))
    monkeypatch.setenv("NNFMU_CACHE_DIR", str(tmp_path / "cache"))
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)
        built = _compiled_paths(tmp_path)
    _check_built(built)
    assert any(os.scandir(tmp_path / "ccache")), "ccache compiled them"


def test_without_a_compiler_the_physics_runs_uncompiled_with_one_warning(tmp_path, monkeypatch):
    from nnfmu.physics.compiled import compile_function

    monkeypatch.setenv("CC", "/nowhere/cc")
    monkeypatch.setenv("NNFMU_CACHE_DIR", str(tmp_path))
    x = ca.SX.sym("x")
    fn = ca.Function("no_cc_physics", [x], [ca.sin(x)])
    with pytest.warns(RuntimeWarning, match=r"^no_cc_physics runs uncompiled \(slower, same values\): "
                                            r"no C compiler found: looked for '/nowhere/cc'") as record:
        assert compile_function(fn) is fn
    assert len(record) == 1 and "\n" not in str(record[0].message)
