"""``nnfmu demo``: the preset of the study pipeline behind the README's main command, on a tiny budget."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

from nnfmu.study import Hyper, get_budget, run_demo


@pytest.fixture(scope="module")
def tiny_demo(tmp_path_factory):
    """The demo with the small valve data and 2 epochs; returns (folder, result, printed lines)."""
    budget = get_budget("valve", "demo").replace(data_size="small", max_train=None, max_test=None, epochs=2,
                                                  max_minutes=None, hyper={"gru": Hyper(hidden=8, batch_size=16)},
                                                  linear={"refine": False, "max_order": 4})
    out = tmp_path_factory.mktemp("demo") / "demo-output"
    lines: list[str] = []
    result = run_demo(out, budget=budget, progress=False, echo=lines.append)
    return out, result, lines, budget


def test_the_demo_preset_is_a_parallel_and_a_series_parallel_gru_at_equal_budgets():
    demo = get_budget("valve", "demo")
    assert demo.archs == ("gru",) and set(demo.strategies) == {"parallel", "series-parallel"}
    assert demo.data_size == "paper" and demo.tune is False


def test_demo_prints_the_four_models_and_where_the_files_are(tiny_demo):
    out, result, lines, _ = tiny_demo
    text = "\n".join(lines)
    rows = {m[1]: float(m[2]) for m in re.finditer(r"^(p-GRU|sp-GRU|Linear[^\n]*?|Physics[^\n]*?)\s+([0-9.]+)\s",
                                                    text, re.MULTILINE)}
    assert len(rows) == 4 and all(np.isfinite(v) for v in rows.values())
    assert {"p-GRU", "sp-GRU"} <= set(rows)
    fmus = [Path(line.strip()) for line in lines if line.strip().endswith(".fmu")]
    assert sorted(f.name for f in fmus) == ["gru-parallel.fmu", "gru-series-parallel.fmu", "linear.fmu", "physics.fmu"]
    assert all(f.is_file() for f in fmus)
    assert any(line.startswith("GRU: ") for line in lines)  # the sentence on the paper's finding
    assert any(str(out / "results.md") in line for line in lines)
    assert all((out / f).is_file() for f in result.results["figures"])


def test_demo_gives_both_strategies_the_same_budget(tiny_demo):
    nets = {n["strategy"]: n for n in tiny_demo[1].results["networks"]}
    p, sp = nets["parallel"], nets["series-parallel"]
    assert p["model_config"] == sp["model_config"]
    assert {k: v for k, v in p["train_config"].items() if k != "strategy"} == \
        {k: v for k, v in sp["train_config"].items() if k != "strategy"}


def test_demo_rerun_skips_what_is_done(tiny_demo):
    out, first, _, budget = tiny_demo
    again = run_demo(out, budget=budget, progress=False, echo=None)
    assert again.log.ran == [] and len(again.log.skipped) == len(first.log.ran)
