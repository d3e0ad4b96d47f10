"""docs/design.md says what the code does: its command list is ``nnfmu --help``'s, it claims no checkpoint
format nnfmu lacks, and its "Adding a physics model" example is a working model that the commands take."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

from nnfmu.physics import registry

ROOT = Path(__file__).resolve().parents[1]
DESIGN = (ROOT / "docs" / "design.md").read_text(encoding="utf-8")


def test_the_command_list_is_that_of_nnfmu_help():
    from nnfmu.cli import build_parser

    commands = next(a for a in build_parser()._actions if hasattr(a, "choices") and a.choices).choices
    listed = re.search(r"cli/\s+one module per command: (.*?)\n\s+\w+\.py", DESIGN, re.S)[1]
    assert sorted(c.strip() for c in listed.split("|")) == sorted(commands)


def test_no_page_claims_safetensors_which_nnfmu_does_not_use():
    pages = [p for p in (ROOT / "docs").rglob("*.md") if "safetensors" in p.read_text(encoding="utf-8")]
    used = any("safetensors" in p.read_text(encoding="utf-8") for p in (ROOT / "nnfmu").rglob("*.py"))
    assert used or pages == []


@pytest.fixture
def tank():
    """The section's example, run as its own module would run; the registry is restored afterwards."""
    section = DESIGN.split("## Adding a physics model")[1].split("\n## ")[0]
    source = re.search(r"```python\n(.*?)```", section, re.S)[1]
    assert len(source.splitlines()) <= 25  # diff-sized
    entries = dict(registry._ENTRIES)
    try:
        exec(compile(source, "tank.py", "exec"), {"__name__": "tank"})
        yield registry.physics_entry("tank")
    finally:
        registry._ENTRIES.clear()
        registry._ENTRIES.update(entries)


def test_the_example_model_is_generated_exported_and_studied(tank, tmp_path):
    from nnfmu.cli import main
    from nnfmu.data import load_dataset
    from nnfmu.study import get_budget
    from nnfmu.study.data_check import check_study_data

    assert main(["generate", "tank", "--size", "small", "-o", str(tmp_path / "ds"), "--quiet"]) == 0
    ds = load_dataset(tmp_path / "ds")
    assert (ds.input_names, ds.output_names) == (["q"], ["h"]) and np.concatenate(ds.train.y).max() > 0.01
    check_study_data("tank", ds, "the tank's data")  # the study takes them
    assert get_budget("tank", "smoke").data_size == "small" and get_budget("tank", "quick").data_size == "standard"
    assert main(["physics-fmu", "tank", "-o", str(tmp_path / "tank.fmu")]) == 0
