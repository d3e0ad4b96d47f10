"""The documentation site builds with --strict (a broken link or API reference fails), from the code itself."""

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent


@pytest.fixture(scope="module")
def site(tmp_path_factory):
    pytest.importorskip("mkdocs", reason="the extra 'docs' is not installed")
    out = tmp_path_factory.mktemp("site")
    env = {**os.environ, "DISABLE_MKDOCS_2_WARNING": "true", "NO_MKDOCS_2_WARNING": "1"}
    run = subprocess.run([sys.executable, "-m", "mkdocs", "build", "--strict", "--site-dir", str(out)],
                         cwd=ROOT, capture_output=True, text=True, env=env)
    assert run.returncode == 0, run.stderr[-3000:]
    return out


def test_every_command_has_a_page_generated_from_its_help(site):
    from nnfmu.cli import build_parser

    commands = next(a for a in build_parser()._actions if hasattr(a, "choices") and a.choices).choices
    for name, parser in commands.items():
        page = (site / "cli" / name / "index.html").read_text()
        for option in (s for a in parser._actions for s in a.option_strings if s.startswith("--")):
            assert option in page, (name, option)
    train = " ".join((site / "cli" / "train" / "index.html").read_text().split())
    assert "train until the budget is spent and keep the best epoch" in train  # today's help, not a copy


def test_api_pages_come_from_the_docstrings(site):
    api = (site / "api" / "index.html").read_text()
    for name in ("from_benchmark", "load_files", "save_dataset", "NrmseResult", "build_fmu", "TrainConfig"):
        assert re.search(rf'id="nnfmu\.[a-z_.]*{name}"', api), name
    assert ":class:" not in api and ":func:" not in api  # reST roles rendered as code


def test_site_holds_the_guides_the_design_and_the_other_issues_pages(site):
    for page in ("tutorial", "data", "concepts", "study", "design", "fmu", "fmu-speed", "accuracy", "scaling"):
        assert (site / page / "index.html").is_file(), page


def test_readme_links_resolve():
    text = (ROOT / "README.md").read_text()
    links = [link for link in re.findall(r"\]\(([^)#]+)\)", text) if "://" not in link]
    assert "docs/design.md" in links
    for link in links:
        assert (ROOT / link).exists(), link
