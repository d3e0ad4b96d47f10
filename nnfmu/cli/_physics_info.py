"""``nnfmu info`` for physics models: a model file (every model it defines), a spec, or a physics document.

Describing a ``.py`` model file runs its code (each argument-free public function is called once to see
whether it returns a model; docs/own-physics.md).
"""

from __future__ import annotations

import dataclasses
import sys
import textwrap
from pathlib import Path


def physics_names() -> tuple[str, ...]:
    """The registered physics models (imported on first use: the registry pulls in CasADi)."""
    from nnfmu.physics import physics_names as names

    return _without_broken_plugins(names)


def study_names() -> tuple[str, ...]:
    """The studies ``nnfmu reproduce`` and ``nnfmu tune --system`` take, from the physics registry."""
    from nnfmu.physics import study_names as names

    return _without_broken_plugins(names)


def _without_broken_plugins(names) -> tuple[str, ...]:
    """A plug-in that cannot be imported must not break every command: say so, and go on without it."""
    from nnfmu.errors import ConfigError

    try:
        return names()
    except ConfigError as exc:
        print(f"nnfmu: warning: {exc}", file=sys.stderr)
        return names(plugins=False)


def is_physics(path: str) -> bool:
    """Whether ``nnfmu info`` should read ``path`` as a physics model (a file spec or a registered name)."""
    from nnfmu.physics.model_file import is_file_spec

    return is_file_spec(path) or (not Path(path).exists() and path in physics_names())


def describe_physics(spec: str) -> dict:
    """``{"kind": "physics", "path", "models": [...]}``: every model of a bare ``.py`` file, else the one named."""
    from nnfmu.physics import resolve_physics
    from nnfmu.physics.model_file import models_in_file, split_spec

    path, name = split_spec(spec)
    if path.suffix.lower() == ".py" and name is None:
        models = models_in_file(path)
        return {"kind": "physics", "path": spec, "models": [_model(s, f"{path}:{n}") for n, s in models.items()]}
    return {"kind": "physics", "path": spec, "models": [_model(resolve_physics(spec), spec)]}


def _model(system, spec: str) -> dict:
    free = set(v.name for v in system.parameters) if system.free_parameters is None else set(system.free_parameters)
    variables = lambda vs: [{k: v for k, v in dataclasses.asdict(x).items() if v is not None} for x in vs]
    return {"spec": spec, "name": system.name, "description": system.description, "Ts": system.Ts,
            "n_sub": system.n_sub,
            "states": [{**d, "scale": s} for d, s in zip(variables(system.states), system.state_scales or
                                                          (1.0,) * system.n_x, strict=True)],
            "inputs": variables(system.inputs), "outputs": variables(system.outputs),
            "parameters": [{**d, "free": d["name"] in free} for d in variables(system.parameters)],
            "source": dict(system.source)}


def render_physics(doc: dict) -> str:
    """Readable lines: per model its spec, description, Ts, then its variables one per line."""
    lines = [f"{doc['path']}: physics model file, {len(doc['models'])} model(s)"
             if len(doc["models"]) != 1 or doc["path"] != doc["models"][0]["spec"] else f"{doc['path']}: physics model"]
    for m in doc["models"]:
        lines.append(f"  {m['spec']}: {m['name']}" + (f" ({m['description']})" if m["description"] else ""))
        lines.append(f"    Ts {m['Ts']:g} s, {m['n_sub']} RK4 sub-steps per sample")
        for role in ("states", "inputs", "outputs", "parameters"):
            if m[role]:
                lines.append(f"    {role}:")
                lines += [f"      {_variable(v, role)}" for v in m[role]]
        if m["source"]:
            pairs = ", ".join(f"{k} {v}" for k, v in m["source"].items() if k != "params")
            lines += textwrap.wrap(f"provenance: {pairs}", 110, initial_indent="    ", subsequent_indent="      ")
    return "\n".join(lines)


def _variable(v: dict, role: str) -> str:
    text = f"{v['name']} [{v.get('unit') or '-'}]"
    if role == "parameters":
        text += f"  nominal {v['start']:.6g}" + ("" if v["free"] else "  fixed")
    elif role == "states":
        text += f"  scale {v['scale']:g}"
    elif v.get("start"):
        text += f"  start {v['start']:.6g}"
    if "min" in v or "max" in v:
        text += f"  {'bounds' if role == 'parameters' else 'range'} {v.get('min', '-')} .. {v.get('max', '-')}"
    return text + (f"  ({v['description']})" if v.get("description") else "")
