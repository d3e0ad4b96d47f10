"""``results.md``: the study's results as Markdown, with the table laid out like the paper's Table I."""

from __future__ import annotations

import math

from nnfmu.physics import study_preset
from nnfmu.training import STRATEGIES

_HEAD = {"series-parallel": "Series-Parallel", "parallel": "Parallel"}


def _fmt(x, digits: int = 3) -> str:
    return "n/a" if x is None or not math.isfinite(x) else f"{x:.{digits}f}"


def table_i(doc: dict) -> list[str]:
    """Rows: architectures; columns: Series-Parallel, Parallel. Bold: the better strategy of a row;
    ``*``: the best network of a column. Baselines follow, their score in the Parallel column."""
    cols = [s for s in ("series-parallel", "parallel") if s in STRATEGIES]
    by_arch: dict[str, dict] = {}
    for n in doc["networks"]:
        by_arch.setdefault(n["arch"], {})[n["strategy"]] = n
    lines = ["| Network | " + " | ".join(_HEAD[c] for c in cols) + " |",
             "| --- | " + " | ".join("---:" for _ in cols) + " |"]
    for arch, cells in by_arch.items():
        scores = {c: cells[c]["nrmse"] if c in cells else None for c in cols}
        finite = {c: v for c, v in scores.items() if v is not None}
        row_best = min(finite, key=finite.get) if len(finite) > 1 else None
        texts = []
        for c in cols:
            text = _fmt(scores[c]) if c in cells else ""
            if c in cells and cells[c]["error"]:
                text = "n/a"  # not scored: the reason is in the notes
            if c == row_best:
                text = f"**{text}**"
            if c in cells and doc["best"].get(c) == cells[c]["name"]:
                text += "*"
            if c in cells:
                text += _spread(cells[c]["training"].get("seeds"))
            texts.append(text)
        lines.append(f"| {arch.upper()} | " + " | ".join(texts) + " |")
    for b in doc["baselines"]:
        lines.append(f"| {b['label']} | " + " | ".join("—" if c != "parallel" else _fmt(b["nrmse"]) for c in cols)
                     + " |")
    return lines


def _spread(seeds: dict | None) -> str:
    """`` (mean, min-max)`` of the seeds' own test scores beside a cell, or nothing for one seed."""
    if not seeds or not seeds.get("test"):
        return ""
    t = seeds["test"]
    return f" ({_fmt(t['mean'])}, {_fmt(t['min'])}–{_fmt(t['max'])})"


def _per_output(doc: dict) -> list[str]:
    outs = doc["dataset"]["outputs"]
    lines = ["| Model | NRMSE | " + " | ".join(outs) + " |",
             "| --- | ---: | " + " | ".join("---:" for _ in outs) + " |"]
    for row in doc["networks"] + doc["baselines"]:
        per = row["per_output"] or {}
        name = row["label"] if row in doc["networks"] else row["name"]
        values = " | ".join(_fmt(per.get(o), 4) for o in outs)
        lines.append(f"| {name} | {_fmt(row['nrmse'], 4)} | {values} |")
    return lines


def _training(doc: dict) -> list[str]:
    head = "| Network | epochs run | best epoch | best valid NRMSE | torch test NRMSE | FMU test NRMSE | time [s] | stop |"
    lines = [head,
             "| --- | ---: | ---: | ---: | ---: | ---: | ---: | --- |"]
    for n in doc["networks"]:
        t = n["training"]
        stop = t["stop_reason"] or ("failed: " + t["error"] if t["error"] else "unfinished")
        if t.get("seeds"):
            stop = f"{t['seeds']['keep']} of {t['seeds']['n']} seeds: " + ", ".join(t["seeds"]["stop_reasons"])
        lines.append(f"| {n['label']} | {t['epochs_run']} | {t['best_epoch']} | {_fmt(t['best_valid_nrmse'], 4)} | "
                     f"{_fmt(t['torch_test_nrmse'], 4)} | {_fmt(n['nrmse'], 4)} | {t['seconds']:.0f} | {stop} |")
    return lines


def _hyper(doc: dict) -> list[str]:
    keys = ("hidden", "layers", "window", "dropout", "lr", "weight_decay", "batch_size", "truncate")
    lines = ["| Network | " + " | ".join(keys) + " |", "| --- | " + " | ".join("---:" for _ in keys) + " |"]
    for n in doc["networks"]:
        merged = {**(n["model_config"] or {}), **(n["train_config"] or {})}
        lines.append(f"| {n['label']} | " + " | ".join(str(merged.get(k)) for k in keys) + " |")
    return lines


def _notes(doc: dict) -> list[str]:
    notes = []
    errors = [(r.get("label"), r["error"]) for r in doc["networks"] + doc["baselines"] if r.get("error")]
    for label, err in errors:
        notes.append(f"- {label}: not scored: {err}")
    for n in doc["networks"]:
        if n["training"]["error"]:
            notes.append(f"- {n['label']}: training failed, the best weights before the failure were used: "
                         f"{n['training']['error']}")
    warned = sorted({w for n in doc["networks"] for w in n["training"].get("notes", []) if w.startswith("WARNING")})
    notes += [f"- Validation: {w[len('WARNING: '):]}" for w in warned]
    for n in doc["networks"]:
        t = n["training"]
        if "time-budget" in [t["stop_reason"], *((t.get("seeds") or {}).get("stop_reasons") or [])]:
            notes.append(f"- {n['label']}: the wall-clock safety net (max_minutes) stopped a training before its "
                         "epochs were done; this number depends on the machine's speed and load.")
    source = doc["dataset"]["source"]
    if source.get("caveat"):
        notes.append(f"- Data caveat: {source['caveat']}")
    noise = source.get("measurement_noise")
    if noise:
        notes.append(f"- Measurement noise: white Gaussian noise of {noise['fraction_of_train_std']:.0%} of each "
                     "output's training standard deviation was added to every split of the generated data, "
                     "because the paper's data were measured; scores are against the noisy measurements.")
    floor = " up to the measurement noise" if noise else ""
    notes.append(f"- {study_preset(doc['system'])[1].note.format(noise_floor=floor)}")
    return notes


_LEGEND = ("Bold: the better training strategy of each network. *: the best network of each column. The "
           "baselines are not trained with either strategy; their free-run score stands in the Parallel column. "
           "With several seeds, a cell scores the kept model (the seeds' ensemble or the best on validation) and "
           "gives the seeds' own test scores in brackets: (mean, min–max).")
_TRAINING = ("Validation: free-run NRMSE on the validation split (early stopping, both strategies); torch test "
             "NRMSE: the float64 free run in torch, which the FMU must reproduce.")


def render_markdown(doc: dict) -> str:
    ds = doc["dataset"]
    test = ds["splits"]["test"]
    lengths = "/".join(str(n) for n in ds["test_lengths"])
    how = "grid-searched on Ray Tune" if doc["tuned"] else "preset"
    intro = (f"Average free-run NRMSE (lower is better) on the test split ({test['n_traj']} trajectories of "
             f"{lengths} samples, Ts = {ds['Ts']:g} s). Every number comes from co-simulating the model's FMU in "
             "fmpy with the test inputs from the measured initial outputs, scored per trajectory as the mean over "
             "outputs.")
    lines = [f"# {study_preset(doc['system'])[1].title}: parallel vs series-parallel training", "",
             f"Budget `{doc['budget']}`, seed {doc['seed']}, hyperparameters {how}; written {doc['written']}.", "",
             intro, "", *table_i(doc), "", _LEGEND, "",
             "## NRMSE per output", "", *_per_output(doc), "",
             "## Training", "", _TRAINING, "", *_training(doc), "",
             "## Hyperparameters", "", *_hyper(doc), ""]
    if doc["figures"]:
        lines += ["## Figures", ""] + [f"![{f}]({f})" for f in doc["figures"]] + [""]
    lines += ["## Notes", "", *_notes(doc), ""]
    return "\n".join(lines)
