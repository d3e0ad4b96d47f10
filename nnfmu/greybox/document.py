"""A grey-box fit on disk: ``{"format": "nnfmu-greybox-fit/1", "physics": <document>, "fit": <report>}``.

``physics`` is :func:`nnfmu.physics.system_to_document` of the fitted model (each free parameter's
``start`` is its estimate), so the file needs neither the user's model file nor any Python of theirs to
be loaded again; ``nnfmu export FIT.json`` and ``nnfmu.physics.resolve_physics("FIT.json")`` read it.
``fit`` is the report, which a script reads for the estimates, the scores, why the solver stopped
(``converged``, ``stopped``) and ``identifiability`` (``flags``: each with ``kind``, ``parameters`` and
``message``; ``correlation``, ``weak_directions``, ``relative_std_error``; an infinite figure is ``null``).
"""

from __future__ import annotations

import json
import math
import os
from pathlib import Path

from nnfmu.atomic import describe_os_error, write_text_atomic
from nnfmu.errors import CheckpointError, DataFileError
from nnfmu.physics.base import PhysicsSystem
from nnfmu.physics.document import system_from_document, system_to_document

__all__ = ["FIT_FORMAT", "fit_document", "save_fit", "load_fit"]

FIT_FORMAT = "nnfmu-greybox-fit/1"


def _json_safe(value):
    """NaN and Inf (a standard error that does not exist) become None, so the file is strict JSON."""
    if isinstance(value, float) and not math.isfinite(value):
        return None
    if isinstance(value, dict):
        return {k: _json_safe(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_json_safe(v) for v in value]
    return value


def fit_document(system: PhysicsSystem, report: dict) -> dict:
    """The JSON document of a fitted ``system`` and its ``report``."""
    return {"format": FIT_FORMAT, "physics": system_to_document(system), "fit": _json_safe(report)}


def save_fit(path: str | os.PathLike, system: PhysicsSystem, report: dict) -> Path:
    """Write the fit to ``path`` atomically (a failed write leaves nothing); returns the path."""
    return write_text_atomic(path, json.dumps(fit_document(system, report), indent=1, allow_nan=False) + "\n")


def load_fit(path: str | os.PathLike) -> tuple[PhysicsSystem, dict]:
    """``(fitted system, report)`` from a file :func:`save_fit` wrote (CheckpointError naming the file if not)."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as exc:
        raise DataFileError(f"cannot read the grey-box fit {describe_os_error(exc, path, doing='read')}") from exc
    try:
        doc = json.loads(text)
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise CheckpointError(f"{path} is not a grey-box fit (not JSON: {exc}); write one with nnfmu fit") from None
    if not isinstance(doc, dict) or doc.get("format") != FIT_FORMAT:
        raise CheckpointError(f"{path} is not a grey-box fit (expected format {FIT_FORMAT!r}); write one with "
                              "nnfmu fit")
    return system_from_document(doc.get("physics")), dict(doc.get("fit") or {})
