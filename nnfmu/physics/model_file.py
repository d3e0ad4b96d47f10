"""A physics model from the user's own Python file (``path/to/file.py:NAME``) or a JSON document.

Loading a ``.py`` file **runs the code in it**, as ``python file.py`` would (but with ``__name__`` not
``"__main__"``): load only files you trust. A model function is a top-level function of the file that takes
no arguments and returns a :class:`PhysicsSystem` (usually through :class:`nnfmu.physics.ModelBuilder`).

- ``file.py:NAME`` calls ``NAME()``;
- ``file.py`` alone works when the file defines exactly one model function: every public (not ``_``-prefixed)
  top-level function without required arguments is called to find out which ones return a model;
- ``file.json``: a physics document (:func:`nnfmu.physics.system_to_document`) or a grey-box fit result
  that holds one under ``"physics"``; no code is run.

Every failure is one :class:`nnfmu.errors.NnfmuError` that names the file: it is missing, it raises (the
exception and the line), NAME is not defined or returns no model, or the model fails :func:`check_system`.
"""

from __future__ import annotations

import dataclasses
import hashlib
import inspect
import json
import sys
import traceback
import types
from pathlib import Path

from nnfmu.errors import CheckpointError, ConfigError, DataFileError, NnfmuError
from nnfmu.physics.base import PhysicsSystem
from nnfmu.physics.builder import check_system

__all__ = ["is_file_spec", "split_spec", "load_module", "model_functions", "models_in_file", "model_from_file",
           "model_from_json"]


def is_file_spec(spec: str) -> bool:
    """Whether ``spec`` names a model file (``.py`` with an optional ``:NAME``, or ``.json``)."""
    path, _ = split_spec(spec)
    return path.suffix.lower() in (".py", ".json")


def split_spec(spec: str) -> tuple[Path, str | None]:
    """``"dir/file.py:NAME"`` -> ``(Path("dir/file.py"), "NAME")``; no ``:NAME`` -> ``(path, None)``."""
    head, sep, tail = str(spec).rpartition(":")
    if sep and head.lower().endswith(".py") and tail and "/" not in tail and "\\" not in tail:
        return Path(head), tail
    return Path(str(spec)), None


def _where(exc: BaseException, path: Path) -> str:
    """``file.py:LINE`` of the deepest frame of ``exc`` in the user's file (the file alone when none is)."""
    lines = [f.lineno for f in traceback.extract_tb(exc.__traceback__) if Path(f.filename) == path]
    return f"{path}:{lines[-1]}" if lines else str(path)


def _raised(exc: BaseException, path: Path, what: str) -> NnfmuError:
    """One error for an exception out of the user's code: the file, its line and the exception."""
    message = f"{_where(exc, path)}: {what} raised {type(exc).__name__}: {exc}"
    if isinstance(exc, NnfmuError):  # keep the class (ShapeError stays a ShapeError)
        return type(exc)(f"{_where(exc, path)}: {what}: {exc}")
    return ConfigError(message + "; fix the model file")


def load_module(path: str | Path):
    """Run a model file and return its module (a DataFileError if it is missing, a ConfigError if it raises)."""
    path = Path(path).resolve()
    if not path.is_file():
        raise DataFileError(f"model file {path} not found; check the path (path/to/file.py:NAME)")
    digest = hashlib.sha1(str(path).encode()).hexdigest()[:12]
    name = f"nnfmu_user_model_{digest}"
    module = types.ModuleType(name)
    module.__file__ = str(path)
    sys.modules[name] = module  # dataclasses and pickling look their module up here
    try:  # compiled here rather than imported: no __pycache__ is written beside the user's file
        exec(compile(path.read_bytes(), str(path), "exec"), module.__dict__)
    except (Exception, SystemExit) as exc:
        sys.modules.pop(name, None)
        if isinstance(exc, SyntaxError):
            raise ConfigError(f"{path}:{exc.lineno}: SyntaxError: {exc.msg}; fix the model file") from None
        raise _raised(exc, path, "loading it") from None
    return module


def model_functions(module) -> dict[str, callable]:
    """The module's own public top-level functions callable without arguments, in file order."""
    found = {}
    for name, fn in vars(module).items():
        if name.startswith("_") or not inspect.isfunction(fn) or fn.__module__ != module.__name__:
            continue
        required = [p for p in inspect.signature(fn).parameters.values()
                    if p.default is p.empty and p.kind in (p.POSITIONAL_ONLY, p.POSITIONAL_OR_KEYWORD, p.KEYWORD_ONLY)]
        if not required:
            found[name] = fn
    return found


def _call(module, path: Path, name: str) -> object:
    try:
        return getattr(module, name)()
    except (Exception, SystemExit) as exc:
        raise _raised(exc, path, f"{name}()") from None


def _checked(system: PhysicsSystem, path: Path, name: str | None) -> PhysicsSystem:
    """``system`` checked, with where it came from in its ``source`` (``file`` and ``function``, or ``document``)."""
    try:
        check_system(system)
    except NnfmuError as exc:
        raise type(exc)(f"{path}{':' + name if name else ''}: {exc}") from None
    where = {"file": str(path), "function": name} if name else {"document": str(path)}
    return dataclasses.replace(system, source={**system.source, **where})


def models_in_file(path: str | Path) -> dict[str, PhysicsSystem]:
    """Every model the file defines, by function name (each candidate function is called once)."""
    path = Path(path).resolve()
    module = load_module(path)
    models = {}
    for name in model_functions(module):
        result = _call(module, path, name)
        if isinstance(result, PhysicsSystem):
            models[name] = _checked(result, path, name)
    return models


def model_from_file(path: str | Path, name: str | None = None) -> PhysicsSystem:
    """The model that ``NAME()`` in the file returns (``name`` None: the file's only model)."""
    path = Path(path).resolve()
    if name is None:
        models = models_in_file(path)
        if len(models) != 1:
            found = f"defines {', '.join(models)}" if models else "defines no function that returns a model"
            raise ConfigError(f"{path} {found}; name one as {path}:NAME")
        return next(iter(models.values()))
    module = load_module(path)
    if not callable(getattr(module, name, None)):
        choices = ", ".join(model_functions(module)) or "no argument-free function"
        raise ConfigError(f"{path} does not define {name}(); it defines {choices}")
    result = _call(module, path, name)
    if not isinstance(result, PhysicsSystem):
        raise ConfigError(f"{path}:{name}() returned {type(result).__name__}, expected a model; end the "
                          f"function with 'return m.build()' (a nnfmu.physics.ModelBuilder)")
    return _checked(result, path, name)


def model_from_json(path: str | Path) -> PhysicsSystem:
    """The model in a physics document or in a grey-box fit result (its ``"physics"``); no code is run."""
    from nnfmu.physics.document import system_from_document

    path = Path(path)
    try:
        doc = json.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise DataFileError(f"{path} not found; give a physics document or a fit result (.json)") from None
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise DataFileError(f"cannot read {path} as JSON ({exc}); give a physics document or a fit result") from None
    if isinstance(doc, dict) and isinstance(doc.get("physics"), dict):
        doc = doc["physics"]
    try:
        system = system_from_document(doc)
    except CheckpointError as exc:
        raise CheckpointError(f"{path}: {exc}") from None
    return _checked(system, path, None)
