"""The study's results: ``results.json`` (every cell), ``results.md`` (Table I and more) and the figures.

All scores are recomputed here with :func:`nnfmu.metrics.nrmse` from the
predictions that fmpy produced for each FMU (the one scoring path), so the
table, the JSON and the figures cannot disagree.
"""

from __future__ import annotations

import math
import time
from pathlib import Path

import numpy as np

from nnfmu.cosim import Evaluation
from nnfmu.data import Dataset, load_dataset
from nnfmu.metrics import nrmse
from nnfmu.physics import study_preset
from nnfmu.study import cell_work
from nnfmu.study.budgets import network_name
from nnfmu.study.report_md import render_markdown
from nnfmu.training import STRATEGIES

STRATEGY_PREFIX = {"parallel": "p", "series-parallel": "sp"}


def _clean(x):
    """JSON has no NaN: non-finite numbers become None."""
    return float(x) if x is not None and math.isfinite(float(x)) else None


def _score(ds: Dataset, study, name: str, label: str) -> tuple[dict, Evaluation | None]:
    preds, error = cell_work.load_scores(study.path("scores", name))
    entry = {"nrmse": None, "per_output": None, "per_trajectory": None, "error": error or None}
    if error:
        return entry, None
    result = nrmse(list(ds.test.y), preds)
    entry.update(nrmse=_clean(result.mean), per_output={n: _clean(v) for n, v in zip(ds.output_names,
                                                                                      result.output_mean)},
                 per_trajectory=[_clean(v) for v in result.per_trajectory])
    return entry, Evaluation(label, study.path("fmus", name), result, preds)


def _network(ds: Dataset, study, arch: str, strategy: str) -> tuple[dict, Evaluation | None]:
    from nnfmu.models import load_checkpoint
    name = network_name(arch, strategy)
    ckpt_path = study.path("models", name)
    ckpt = load_checkpoint(ckpt_path)
    summary = ckpt.get("summary") or {}
    label = f"{STRATEGY_PREFIX[strategy]}-{arch.upper()}"
    entry, evaluation = _score(ds, study, name, label)
    failed = cell_work.error_file(ckpt_path)
    seeds = summary.get("seeds") or []
    per_seed = (lambda key: ", ".join(str(r.get(key)) for r in seeds)) if seeds else None
    training = {"epochs_run": per_seed("epochs_run") if seeds else summary.get("epochs_run"),
                "best_epoch": per_seed("best_epoch") if seeds else ckpt.get("best_epoch"),
                "best_valid_nrmse": _clean(summary.get("best_valid_nrmse")),
                "torch_test_nrmse": _clean(summary.get("test_nrmse")), "stop_reason": summary.get("stop_reason"),
                "seconds": float(sum(h.get("seconds", 0.0) for h in ckpt.get("history", []))
                                 + sum(r.get("seconds") or 0.0 for r in seeds)),
                "error": failed.read_text().strip() if failed.exists() else None,
                "valid_samples": summary.get("valid_samples"), "notes": summary.get("notes") or [],
                "seeds": seed_summary(seeds, summary.get("keep"))}
    paths = {k: _rel(study, study.path(k, name)) for k in ("models", "fmus", "scores")}
    return ({"name": name, "label": label, "arch": arch, "strategy": strategy, **entry, "training": training,
             "model_config": ckpt.get("model_config"), "train_config": ckpt.get("train_config"), "paths": paths},
            evaluation)


def seed_summary(rows: list[dict], keep: str | None) -> dict | None:
    """Spread of the seeds' own scores (mean, min, max) and their stop reasons; None for one seed."""
    if not rows:
        return None

    def spread(key: str) -> dict:
        vals = [r[key] for r in rows if r.get(key) is not None and math.isfinite(r[key])]
        return {"mean": float(np.mean(vals)), "min": float(min(vals)), "max": float(max(vals))} if vals else None

    return {"n": len(rows), "keep": keep, "test": spread("test_nrmse"), "valid": spread("best_valid_nrmse"),
            "stop_reasons": [r.get("stop_reason") for r in rows],
            "per_seed": [{k: r.get(k) for k in ("seed", "best_valid_nrmse", "test_nrmse", "best_epoch", "epochs_run",
                                                "stop_reason", "error")} for r in rows]}


def _baselines(ds: Dataset, study) -> list[tuple[dict, Evaluation | None]]:
    import json

    info = json.loads((study.out / "models" / "linear.json").read_text()).get("info", {})
    order = info.get("order") or info.get("n_x")
    physics = study_preset(study.system)[1].physics_label
    rows = []
    for name, label, extra in (("linear", "Linear state-space baseline" + (f" (n_x = {order})" if order else ""),
                                {"identification": info}),
                               ("physics", physics, {})):
        entry, evaluation = _score(ds, study, name, name)
        paths = {"fmus": _rel(study, study.path("fmus", name)), "scores": _rel(study, study.path("scores", name))}
        if name == "linear":
            paths["models"] = "models/linear.json"
        rows.append(({"name": name, "label": label, **entry, **extra, "paths": paths}, evaluation))
    return rows


def _rel(study, path: Path) -> str:
    return str(path.relative_to(study.out))


def best_of(networks: list[dict]) -> dict[str, str | None]:
    """Per strategy, the name of the network with the lowest NRMSE (None if none was scored)."""
    best = {}
    for strategy in STRATEGIES:
        scored = [n for n in networks if n["strategy"] == strategy and n["nrmse"] is not None]
        best[strategy] = min(scored, key=lambda n: n["nrmse"])["name"] if scored else None
    return best


def _figures(study, ds: Dataset, best: dict, evaluations: dict) -> list[str]:
    from nnfmu.plots import plot_trajectory

    chosen = [evaluations[best[s]] for s in STRATEGIES if best[s] and evaluations.get(best[s])]
    with_baselines = chosen[:1] + [evaluations[n] for n in ("linear", "physics") if evaluations.get(n)]
    # Fig. 2 (valve): one representative test trajectory; Fig. 3 (robot, arm): the whole test record.
    index = 0 if study_preset(study.system)[1].whole_record else None
    out = []
    for stem, evs in (("best_parallel_vs_series_parallel", chosen), ("best_network_vs_baselines", with_baselines)):
        if evs:
            path = plot_trajectory(ds, evs, study.out / "figures" / f"{stem}.png", index=index)
            out.append(_rel(study, path))
    return out


def collect(study) -> tuple[dict, Dataset]:
    """The results document (see ``results.json``) of a study whose score cells are done."""
    ds = load_dataset(study.data_dir)
    networks, evaluations = [], {}
    for arch, strategy in study.networks:
        entry, ev = _network(ds, study, arch, strategy)
        networks.append(entry)
        evaluations[entry["name"]] = ev
    baselines = []
    for entry, ev in _baselines(ds, study):
        baselines.append(entry)
        evaluations[entry["name"]] = ev
    best = best_of(networks)
    test = ds.test
    doc = {"format": "nnfmu-study-results", "system": study.system, "budget": study.budget.name,
           "seed": study.seed, "tuned": study.tune, "written": time.strftime("%Y-%m-%d %H:%M:%S"),
           "scoring": "free-run NRMSE on the test split, FMUs co-simulated in fmpy from the measured y0; "
                      "per trajectory the mean over outputs, then the mean over trajectories",
           "dataset": {"path": "data", "Ts": ds.Ts, "inputs": ds.input_names, "outputs": ds.output_names,
                       "splits": {k: {"n_traj": v.n_traj, "n_samples": int(v.n_samples)} for k, v in ds.splits.items()},
                       "source": ds.source, "test_lengths": sorted(set(test.lengths.tolist()))},
           "networks": networks, "baselines": baselines, "best": best,
           "budget_settings": study.budget.to_json()}
    doc["figures"] = _figures(study, ds, best, evaluations)
    return doc, ds


def write_results(study) -> str:
    """Write ``results.json``, ``results.md`` and the figures; returns a one-line summary."""
    doc, _ = collect(study)
    md = render_markdown(doc)
    cell_work.write_json(study.out / "results.json", doc)
    cell_work.write_text_atomic(study.out / "results.md", md)
    parts = []
    for strategy in STRATEGIES:
        name = doc["best"][strategy]
        if name:
            row = next(n for n in doc["networks"] if n["name"] == name)
            parts.append(f"best {strategy} {row['label']} {row['nrmse']:.4f}")
    return "; ".join(parts) or "no network was scored"
