"""``nnfmu info FILE.fmu|FILE.pt|DATASET|MODEL.py[:NAME]|MODEL.json|valve [--json]``: what a file, dataset
folder or physics model is.

An FMU: its model, FMI version, platforms, Ts, inputs, outputs and parameters
with units and ranges, and who generated it. A checkpoint: the network, the
data it was trained on (channels, Ts, provenance), the training settings and
how it ended. A dataset folder: Ts, channels with units and their range in the
train split (as ``nnfmu import`` prints it) and over all splits, splits, init
window and provenance. A physics model (nnfmu.cli._physics_info): each model a ``.py`` file defines (running
the file), or the one a spec names, with its states, inputs, outputs and parameters (nominal, bounds, free).

The text is a readable summary, one fact per line; ``--json`` prints the raw
description (where a run bounded by its time budget alone stores
``epochs = nnfmu.limits.UNBOUNDED_EPOCHS``, which the text calls "unbounded").
"""

from __future__ import annotations

import argparse
import json
import textwrap
from pathlib import Path


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("info", help="describe an FMU, a checkpoint, a dataset folder or a physics model",
                       description="Describe an FMU (.fmu), a training checkpoint (.pt), a dataset folder or a physics "
                                   "model (file.py lists the models it defines, running its code; file.py:NAME, a "
                                   ".json physics document, or a built-in name): inputs, outputs, units, Ts, ranges, "
                                   "parameters, provenance and the training summary.")
    p.add_argument("path", help="an .fmu file, a .pt checkpoint, a dataset folder or a physics model")
    p.add_argument("--json", action="store_true", help="print the raw description as JSON (default: a readable "
                                                       "summary)")
    p.set_defaults(func=_run)


def describe(path: str | Path) -> dict:
    """A JSON-ready description of an FMU, a checkpoint or a dataset folder (chosen by what ``path`` is)."""
    from nnfmu.cli._physics_info import describe_physics, is_physics
    from nnfmu.errors import DataFileError

    if is_physics(str(path)):
        return describe_physics(str(path))
    path = Path(path)
    if path.is_dir():
        return _dataset(path)
    if path.suffix.lower() == ".fmu":
        return _fmu(path)
    if path.suffix.lower() in (".pt", ".pth"):
        return _checkpoint(path)
    if not path.exists():
        raise DataFileError(f"{path} not found; give an .fmu file, a .pt checkpoint, a dataset folder or a physics "
                            f"model (file.py[:NAME], .json, or a built-in name)")
    raise DataFileError(f"{path} is neither an .fmu, a .pt checkpoint, a dataset folder nor a physics model")


def _range(values) -> list[float]:
    return [float(min(values)), float(max(values))]


def _dataset(path: Path) -> dict:
    import numpy as np

    from nnfmu.data import load_dataset

    ds = load_dataset(path)
    every = {k: np.concatenate([a for tr in ds.splits.values() for a in getattr(tr, k)]) for k in ("u", "y")}
    train = {k: np.concatenate(list(getattr(ds.train, k))) for k in ("u", "y")}

    def channels(chans, k: str) -> list[dict]:
        return [{**c.to_json(), "train_range": _range(train[k][:, j]), "range": _range(every[k][:, j])}
                for j, c in enumerate(chans)]

    return {"kind": "dataset", "path": str(path), "Ts": ds.Ts, "inputs": channels(ds.inputs, "u"),
            "outputs": channels(ds.outputs, "y"), "init_window": ds.init_window,
            "splits": {k: {"n_traj": v.n_traj, "n_samples": v.n_samples, "lengths": sorted(set(v.lengths.tolist()))}
                       for k, v in ds.splits.items()},
            "source": ds.source}


def _fmu(path: Path) -> dict:
    import fmpy

    from nnfmu.cosim import inspect_fmu

    inspect_fmu(path)  # a clear error for a missing or broken file
    md = fmpy.read_model_description(str(path), validate=False)

    def variable(v) -> dict:
        unit = v.unit or (v.declaredType.unit if getattr(v, "declaredType", None) is not None else None)
        out = {"name": v.name, "unit": unit or "", "description": v.description or ""}
        for key in ("start", "min", "max"):
            value = getattr(v, key, None)
            if value not in (None, ""):
                out[key] = float(value) if _is_number(value) else value
        return out

    by = {c: [variable(v) for v in md.modelVariables if v.causality == c] for c in ("input", "output", "parameter")}
    step = md.defaultExperiment.stepSize if md.defaultExperiment is not None else None
    return {"kind": "fmu", "path": str(path), "model": md.modelName, "fmi_version": md.fmiVersion,
            "interfaces": [k for k, v in (("co-simulation", md.coSimulation), ("model exchange", md.modelExchange))
                           if v is not None],
            "platforms": fmpy.supported_platforms(str(path)), "Ts": None if step is None else float(step),
            "inputs": by["input"], "outputs": by["output"], "parameters": by["parameter"],
            "description": md.description, "generation_tool": md.generationTool,
            "generated": md.generationDateAndTime, "step_cost": _fmu_step_cost(path)}


def _fmu_step_cost(path: Path) -> dict | None:
    """The step's weights, bytes and FLOPs from the C the FMU ships (None for an FMU without nnfmu's sources)."""
    import zipfile

    from nnfmu.errors import FmuBuildError
    from nnfmu.export.step_cost import source_cost

    with zipfile.ZipFile(path) as z:
        if "sources/model_casadi.c" not in z.namelist():
            return None
        source = z.read("sources/model_casadi.c").decode("utf-8", errors="replace")
    try:
        return source_cost(source).as_dict()
    except FmuBuildError:
        return None


def _checkpoint_step_cost(path: Path) -> dict | str:
    """The float64 FMU step's weights, bytes and FLOPs, from the model's CasADi step (as ``nnfmu export`` builds it)."""
    from nnfmu.errors import NnfmuError
    from nnfmu.export import to_casadi
    from nnfmu.export.step_cost import function_cost
    from nnfmu.models import load_model

    try:
        _, step = to_casadi(load_model(path).double(), verify=False)
    except NnfmuError as exc:  # the rest of the description stands without it
        return f"unknown: the checkpoint does not export ({exc})"
    return function_cost(step).as_dict()


def _is_number(value) -> bool:
    try:
        float(value)
    except (TypeError, ValueError):
        return False
    return True


def _checkpoint(path: Path) -> dict:
    from nnfmu.models import load_checkpoint

    ckpt = load_checkpoint(path)
    meta, state = ckpt["meta"], ckpt["state_dict"]
    stats = lambda kind, chans: [{**c, "mean": float(state[f"{kind}_mean"][j]), "std": float(state[f"{kind}_std"][j])}
                                 if f"{kind}_mean" in state else dict(c) for j, c in enumerate(chans)]
    history = ckpt.get("history") or []
    summary = dict(ckpt.get("summary") or {})
    seconds = sum(h.get("seconds", 0.0) for h in history) + sum(r.get("seconds") or 0.0
                                                               for r in summary.get("seeds") or [])
    summary.update(best_epoch=ckpt.get("best_epoch"), seconds=float(seconds), resumable=ckpt.get("resume") is not None)
    config = dict(ckpt["model_config"])
    if isinstance(config.get("physics_document"), dict):  # a hybrid on a user's model: name it, not its bytes
        doc = config["physics_document"]
        config["physics_document"] = f"{doc.get('name')} ({len(doc.get('states', []))} states; stored inside)"
    if config.get("member_configs"):  # a mixed ensemble: each member in a few words, not its whole config
        config["member_configs"] = [f"{m['arch']} hidden {m['hidden']} layers {m['layers']}"
                                    for m in config["member_configs"]]
    return {"kind": "checkpoint", "path": str(path), "name": meta.get("name"), "Ts": meta.get("Ts"),
            "model_config": config, "train_config": ckpt.get("train_config"),
            "inputs": stats("u", meta.get("inputs", [])), "outputs": stats("y", meta.get("outputs", [])),
            "training": summary, "source": meta.get("source", {}), "step_cost": _checkpoint_step_cost(path)}


_TITLES = {"init_window": "init window", "model_config": "network", "train_config": "training settings",
           "training": "training result", "source": "provenance"}


def render(doc: dict) -> str:
    """The description as readable lines: a heading, the channels, then one indented line per setting."""
    if doc["kind"] == "physics":
        from nnfmu.cli._physics_info import render_physics

        return render_physics(doc)
    lines = [f"{doc['path']}: {doc['kind']}"]
    head = {"dataset": ("Ts",), "fmu": ("model", "description", "fmi_version", "interfaces", "platforms", "Ts",
                                        "generation_tool", "generated"), "checkpoint": ("name", "Ts")}[doc["kind"]]
    lines += [f"  {key}: {_text(doc[key])}" + (" s" if key == "Ts" else "") for key in head
              if doc.get(key) not in (None, [], "")]
    if doc["kind"] == "dataset":
        lines.append("  ranges: in the train split (as 'nnfmu import' prints them), then over all splits")
    for role in ("inputs", "outputs", "parameters"):
        if doc.get(role):
            lines.append(f"  {role}:")
            lines += [f"    {_channel(c)}" for c in doc[role]]
    if doc.get("splits"):
        lines.append("  splits:")
        lines += [f"    {name}: {s['n_traj']} trajectories, {s['n_samples']} samples (lengths "
                  f"{', '.join(map(str, s['lengths']))})" for name, s in doc["splits"].items()]
    if doc.get("step_cost"):
        lines.append(f"  step cost: {_cost(doc['step_cost'])}")
    for key in ("init_window", "model_config", "train_config", "training", "source"):
        value = doc.get(key)
        if value in (None, {}, []):
            continue
        if not isinstance(value, dict):
            lines.append(f"  {_TITLES.get(key, key)}: {_text(value, key)}")
            continue
        pairs = [f"{k} {_text(v, k)}" for k, v in value.items() if v not in (None, "", [], {})]
        lines.append(f"  {_TITLES.get(key, key)}:")
        lines += textwrap.wrap(", ".join(pairs), 110, initial_indent="    ", subsequent_indent="    ",
                               break_on_hyphens=False)
    return "\n".join(lines)


def _cost(cost: dict | str) -> str:
    """``3302 weights read per step (26.4 kB in float64), 6604 FLOPs in matrix products``."""
    if isinstance(cost, str):
        return cost
    return (f"{cost['weights']} weights read per step ({cost['weight_bytes'] / 1000:.1f} kB in {cost['precision']}), "
            f"{cost['flops']} FLOPs in matrix products (docs/fmu-speed.md)")


def _channel(c: dict) -> str:
    text = f"{c['name']} [{c.get('unit') or '-'}]"
    if "train_range" in c:
        text += f"  range {c['train_range'][0]:.4g} .. {c['train_range'][1]:.4g}"
        if c.get("range") and c["range"] != c["train_range"]:
            text += f" (all splits {c['range'][0]:.4g} .. {c['range'][1]:.4g})"
    elif "range" in c:
        text += f"  range {c['range'][0]:.4g} .. {c['range'][1]:.4g}"
    if "min" in c or "max" in c:
        text += f"  min {c.get('min', '-')}, max {c.get('max', '-')}"
    if "mean" in c:
        text += f"  training data mean {c['mean']:.4g}, std {c['std']:.4g}"
    if "start" in c:
        text += f"  start {c['start']:.6g}" if isinstance(c["start"], float) else f"  start {c['start']}"
    return text + (f"  ({c['description']})" if c.get("description") else "")


def _text(value, key: str = "") -> str:
    """One value as text: lists joined by commas, dicts as ``key value`` pairs, the epoch sentinel in words."""
    from nnfmu.limits import UNBOUNDED_EPOCHS

    if key == "epochs" and value == UNBOUNDED_EPOCHS:
        return "unbounded (time budget)"
    if key == "seconds" and isinstance(value, (int, float)):
        return f"{value:.1f} s"
    if key == "seeds" and isinstance(value, list) and all(isinstance(r, dict) for r in value):
        return "; ".join(_seed(r) for r in value)
    if isinstance(value, bool) or value is None:
        return {True: "yes", False: "no", None: "-"}[value]
    if isinstance(value, list):
        return ", ".join(_text(v) for v in value)
    if isinstance(value, dict):
        return "; ".join(f"{k} {_text(v, k)}" for k, v in value.items())
    return f"{value:g}" if isinstance(value, float) else str(value)


def _seed(row: dict) -> str:
    """One seed of a model kept of several (``nnfmu train --seeds``, or the plan's two) in a few words."""
    score = lambda v: "-" if v is None else f"{v:.4f}"
    return (f"seed {row.get('seed')}: validation {score(row.get('best_valid_nrmse'))}, test "
            f"{score(row.get('test_nrmse'))}, best epoch {row.get('best_epoch')} of {row.get('epochs_run')}, "
            f"{row.get('stop_reason')}" + (f" ({row['error']})" if row.get("error") else ""))


def _run(args: argparse.Namespace) -> int:
    doc = describe(args.path)
    print(json.dumps(doc, indent=2, default=str) if args.json else render(doc))
    return 0
