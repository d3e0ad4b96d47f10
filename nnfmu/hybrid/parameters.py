"""The physics of a hybrid by name or document, and its parameter overrides (:class:`~nnfmu.hybrid.HybridConfig`).

- :func:`physics_system` (a registered model, built once) and :func:`document_system` (a physics
  document's JSON text, deserialized once): what :meth:`HybridConfig.system` returns;
- :func:`normalise_physics_params` and :func:`load_physics_params`: a JSON object of parameter names and
  numbers (a tuple field may be a list), checked against the physics' ``p`` vector;
- :func:`kinematic_states`: the states whose derivative is exactly another state (``dpos/dt = v``), which a
  hybrid's correction leaves alone by default;
- :func:`ignorable_states`: the states no derivative depends on (a position on a rail), which a hybrid's
  correction does not see by default, and :func:`hide_state_inputs`, which keeps them out of its network.
"""

from __future__ import annotations

import functools
import json
import math
import os
from typing import Mapping

import casadi as ca
import torch

from nnfmu.atomic import describe_os_error
from nnfmu.errors import CheckpointError, ConfigError, DataFileError, UnknownOptionError
from nnfmu.physics import PhysicsSystem
from nnfmu.physics.document import system_from_document
from nnfmu.physics.registry import physics_entry, physics_names

__all__ = ["physics_system", "document_system", "document_text", "registered_defaults",
           "normalise_physics_params", "load_physics_params", "kinematic_states", "ignorable_states",
           "hide_state_inputs"]


@functools.lru_cache(maxsize=None)
def physics_system(name: str) -> PhysicsSystem:
    """The nominal registered :class:`PhysicsSystem` called ``name`` (built once per process)."""
    return physics_entry(name).build()


@functools.lru_cache(maxsize=8)
def document_system(text: str) -> PhysicsSystem:
    """The :class:`PhysicsSystem` of a physics document given as JSON text (built once per document)."""
    return system_from_document(json.loads(text))


def document_text(doc) -> str:
    """Canonical JSON text of a physics document (a dict, or JSON text): hashable, comparable, stored."""
    if isinstance(doc, str):
        try:
            doc = json.loads(doc)
        except json.JSONDecodeError as exc:
            raise CheckpointError(f"the hybrid's stored physics document is not valid JSON ({exc}); "
                                  "train or export the hybrid again") from exc
    if not isinstance(doc, Mapping):
        raise CheckpointError(f"the hybrid's physics document must be a JSON object, got {type(doc).__name__}")
    return json.dumps(dict(doc), sort_keys=True, separators=(",", ":"))


def registered_defaults(system: PhysicsSystem, name: str | None):
    """The registry's entry whose defaults apply to ``system`` (its own name's, if the states match), or None."""
    name = system.name if name is None else name
    if name not in physics_names():
        return None
    entry = physics_entry(name)
    states = {v.name for v in system.states}
    return entry if set(entry.corrected_states or ()) <= states else None


def kinematic_states(system: PhysicsSystem) -> tuple[str, ...]:
    """Names of the states whose derivative in ``system.ode`` is exactly another state (``dpos/dt = v``).

    Such a derivative is a kinematic identity, not a model of a force or a flow: nothing is missing there
    for a correction to supply. Correcting it anyway lets the network add a velocity of its own to the
    position, which an integrating output turns into drift; on the viscous slider fitted to Stribeck data
    the first two optimiser steps took the validation NRMSE from 0.477 to 0.746 with ``pos`` corrected,
    and to 0.40 after six with ``v`` alone.
    """
    ode = system.ode.expand() if system.ode.is_a("MXFunction") else system.ode
    x = ca.SX.sym("x", system.n_x)
    xdot = ode(x, ca.SX.sym("u", ode.size1_in(1)), ca.SX.sym("p", ode.size1_in(2)))
    return tuple(v.name for i, v in enumerate(system.states)
                 if any(j != i and ca.is_equal(xdot[i], x[j]) for j in range(system.n_x)))


def ignorable_states(system: PhysicsSystem) -> tuple[str, ...]:
    """Names of the states that no derivative of ``system.ode`` depends on (structurally), such as ``pos`` on a rail.

    The model says its dynamics do not change when such a state is shifted (a cyclic coordinate); it
    is an integral, which on an integrating plant wanders beyond any range the training records cover.
    On the viscous slider fitted to Stribeck data, a correction that saw ``pos`` too reached a best
    validation NRMSE of 0.20 in 120 optimiser steps, against 0.149 with ``v`` and the force alone.
    """
    ode = system.ode.expand() if system.ode.is_a("MXFunction") else system.ode
    x = ca.SX.sym("x", system.n_x)
    xdot = ode(x, ca.SX.sym("u", ode.size1_in(1)), ca.SX.sym("p", ode.size1_in(2)))
    return tuple(v.name for i, v in enumerate(system.states) if not ca.depends_on(xdot, x[i]))


def hide_state_inputs(first, columns) -> None:
    """Keep the ``columns`` (state indices) of the correction's first Linear ``first`` at zero: set and gradient.

    The network then cannot see those states in any path that reads its weights (torch, the fused C
    step, the FMU). Zero gradients leave a zero weight where Adam(W) puts it: no update, no decay.
    """
    columns = [int(c) for c in columns]
    if not columns:
        return
    with torch.no_grad():
        first.weight[:, columns] = 0.0

    def zero_columns(grad: torch.Tensor) -> torch.Tensor:
        grad = grad.clone()
        for c in columns:  # plain slices: no index tensor to copy to the device (a CUDA graph records this)
            grad[:, c] = 0.0
        return grad

    first.weight.register_hook(zero_columns)


def _number(name: str, value) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise ConfigError(f"physics parameter {name!r} must be a finite number, got {value!r}")
    return float(value)


def normalise_physics_params(physics: str | PhysicsSystem, params: Mapping,
                             label: str | None = None) -> tuple[tuple[str, float], ...]:
    """Check parameter overrides against ``physics``' ``p`` names; sorted ``(name, value)`` pairs.

    ``physics``: a registered name or the system itself (``label`` names it in messages).

    A list value expands a tuple field: ``{"f_vis": [a, ..]}`` -> ``f_vis1 = a, ...``.
    Raises UnknownOptionError (listing the valid names) or ConfigError (bad value).
    """
    if not isinstance(params, Mapping):
        raise ConfigError(f"physics parameters must be a mapping of name -> number, got {type(params).__name__}")
    system = physics if isinstance(physics, PhysicsSystem) else physics_system(physics)
    physics = label or (system.name if isinstance(physics, PhysicsSystem) else physics)
    valid = [v.name for v in system.parameters]
    out: dict[str, float] = {}
    for name, value in params.items():
        if isinstance(value, (list, tuple)):
            names = [f"{name}{j + 1}" for j in range(len(value))]
            if not all(n in valid for n in names) or f"{name}{len(value) + 1}" in valid:
                raise ConfigError(f"physics parameter {name!r} got a list of {len(value)} values, but {physics} has "
                                  f"no tuple parameter {name!r} of that length; give scalars by entry name")
            out.update((n, _number(n, v)) for n, v in zip(names, value))
        else:
            out[str(name)] = _number(str(name), value)
    unknown = sorted(set(out) - set(valid))
    if unknown:
        raise UnknownOptionError(f"unknown {physics} parameter(s) {', '.join(map(repr, unknown))}; valid names are: "
                                 f"{', '.join(valid)}")
    return tuple(sorted(out.items()))


def load_physics_params(path: str | os.PathLike) -> dict:
    """Read a JSON parameter file (an object of name -> number or list); see the module docstring."""
    try:
        with open(path, encoding="utf-8") as f:
            data = json.load(f)
    except FileNotFoundError:
        raise DataFileError(f"physics parameter file {path} not found; pass a JSON file such as "
                            '{"k_s": 32500.0, "C_max": 4.2e-10}') from None
    except OSError as exc:
        raise DataFileError(f"cannot read the physics parameter file {describe_os_error(exc, path, doing='read')}"
                            ) from exc
    except UnicodeDecodeError as exc:
        raise DataFileError(f"cannot read the physics parameter file {path}: {exc}; save it as UTF-8 JSON") from exc
    except json.JSONDecodeError as exc:
        raise ConfigError(f"physics parameter file {path} is not valid JSON ({exc}); write an object such as "
                          '{"k_s": 32500.0, "C_max": 4.2e-10}') from exc
    if not isinstance(data, dict):
        raise ConfigError(f"physics parameter file {path} must hold a JSON object of name -> number, "
                          f"got a {type(data).__name__}")
    return data
