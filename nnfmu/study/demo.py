"""``nnfmu demo``: the README's main job, as a small preset of the study pipeline.

It generates valve data, trains a parallel and a series-parallel GRU at equal
budgets (same hyperparameters, epochs and seed), exports both as FMUs, builds
the linear and the physics FMUs, co-simulates all four in fmpy and prints the
table. It is :func:`nnfmu.study.reproduce` with the budget ``BUDGETS["valve"]["demo"]``,
so it is resumable the same way: running it again skips what is done.
"""

from __future__ import annotations

from pathlib import Path
from typing import Callable

from nnfmu.study.budgets import Budget, get_budget
from nnfmu.study.pipeline import StudyResult, reproduce

DEMO_OUT = "demo-output"


def text_table(doc: dict) -> str:
    """A plain-text table of every model of a results document: NRMSE and per-output values."""
    outs = doc["dataset"]["outputs"]
    rows = [(n["label"], n["nrmse"], n["per_output"]) for n in doc["networks"]]
    rows += [(b["label"], b["nrmse"], b["per_output"]) for b in doc["baselines"]]
    width = max(len(r[0]) for r in rows)

    def fmt(v) -> str:
        return f"{v:8.4f}" if v is not None else f"{'n/a':>8}"

    head = f"{'model':<{width}}  {'NRMSE':>8}  " + "  ".join(f"{o:>8}" for o in outs)
    lines = [head, "-" * len(head)]
    for label, mean, per in rows:
        lines.append(f"{label:<{width}}  {fmt(mean)}  " + "  ".join(fmt((per or {}).get(o)) for o in outs))
    return "\n".join(lines)


def finding(doc: dict) -> str:
    """One sentence on the paper's finding for the networks of the document."""
    by = {(n["arch"], n["strategy"]): n["nrmse"] for n in doc["networks"]}
    lines = []
    for arch in dict.fromkeys(n["arch"] for n in doc["networks"]):
        p, sp = by.get((arch, "parallel")), by.get((arch, "series-parallel"))
        if p is None or sp is None:
            lines.append(f"{arch.upper()}: one of the two models could not be scored; see results.md")
        elif p < sp:
            lines.append(f"{arch.upper()}: parallel training beats series-parallel training at an equal budget "
                         f"(test NRMSE {p:.4f} vs {sp:.4f}, {sp / p:.1f} times lower), as the paper found.")
        else:
            lines.append(f"{arch.upper()}: here series-parallel training scored {sp:.4f} and parallel {p:.4f}; "
                         "the paper's finding did not show at this budget.")
    return "\n".join(lines)


def run_demo(out: str | Path = DEMO_OUT, *, budget: Budget | None = None, seed: int = 0, progress: bool = True,
             echo: Callable[[str], None] | None = print) -> StudyResult:
    """Run (or resume) the demo into ``out`` and print the table and where the FMUs and figures are.

    ``budget`` defaults to ``BUDGETS["valve"]["demo"]``; tests pass a smaller one.
    """
    budget = budget or get_budget("valve", "demo")
    result = reproduce("valve", out, budget=budget, seed=seed, tune=False, progress=progress, echo=echo)
    if echo:
        doc, root = result.results, Path(out)
        fmus = [root / n["paths"]["fmus"] for n in doc["networks"] + doc["baselines"]]
        echo("")
        echo(f"Free-run NRMSE on {doc['dataset']['splits']['test']['n_traj']} test trajectories, every model "
             "co-simulated as an FMU in fmpy:")
        echo(text_table(doc))
        echo("")
        echo(finding(doc))
        echo("")
        echo("FMUs (FMI 2.0 co-simulation, standalone C):")
        for path in fmus:
            echo(f"  {path}")
        echo("Figures: " + ", ".join(str(root / f) for f in doc["figures"]))
        echo(f"Table, training details and notes: {root / 'results.md'}")
    return result
