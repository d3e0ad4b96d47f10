"""A :class:`PhysicsSystem` as a JSON document: its CasADi Functions serialized, never Python.

Checkpoints and fitted models store the physics they were made from this way, so that
loading, exporting and scoring them again needs neither the user's model file nor any
Python code of theirs: CasADi's own serialization holds the ODE, the output map and the
initial-state rule; names, units, bounds and nominal values are plain JSON.
"""

from __future__ import annotations

import dataclasses

import casadi as ca

from nnfmu.errors import CheckpointError
from nnfmu.physics.base import PhysicsSystem
from nnfmu.system import Variable

__all__ = ["DOCUMENT_FORMAT", "system_to_document", "system_from_document"]

DOCUMENT_FORMAT = "nnfmu-physics/1"
_FUNCTIONS = ("ode", "output", "init_state")
_VARIABLES = ("states", "inputs", "outputs", "parameters")


def system_to_document(system: PhysicsSystem) -> dict:
    """``system`` as a JSON-serialisable dict (CasADi Functions as their serialized strings)."""
    doc = {"format": DOCUMENT_FORMAT, "name": system.name, "Ts": float(system.Ts), "n_sub": int(system.n_sub),
           "state_scales": [float(s) for s in system.state_scales], "description": system.description,
           "source": dict(system.source),
           "free_parameters": None if system.free_parameters is None else list(system.free_parameters)}
    for key in _FUNCTIONS:
        doc[key] = getattr(system, key).serialize()
    for key in _VARIABLES:
        doc[key] = [dataclasses.asdict(v) for v in getattr(system, key)]
    return doc


def system_from_document(doc: dict) -> PhysicsSystem:
    """The :class:`PhysicsSystem` a :func:`system_to_document` dict holds (CheckpointError if it is not one)."""
    if not isinstance(doc, dict) or doc.get("format") != DOCUMENT_FORMAT:
        raise CheckpointError(f"not a physics model document (expected format {DOCUMENT_FORMAT!r}); "
                              f"make it with nnfmu.physics.document.system_to_document")
    try:
        functions = {key: ca.Function.deserialize(doc[key]) for key in _FUNCTIONS}
        variables = {key: tuple(Variable(**v) for v in doc[key]) for key in _VARIABLES}
        free = doc.get("free_parameters")
        return PhysicsSystem(name=doc["name"], Ts=float(doc["Ts"]), n_sub=int(doc["n_sub"]),
                             state_scales=tuple(doc.get("state_scales", ())), description=doc.get("description", ""),
                             source=dict(doc.get("source", {})), free_parameters=None if free is None else tuple(free),
                             **functions, **variables)
    except (KeyError, TypeError, RuntimeError) as exc:
        raise CheckpointError(f"the physics model document is damaged ({exc}); export the model again") from exc
