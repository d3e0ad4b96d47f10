"""The documentation site builds with --strict (a broken link or API reference fails), from the code itself."""

import json
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
    assert "spend the budget on a small search" in train  # today's help, not a copy


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


PUBLIC_MODULES = ("nnfmu", "nnfmu.data", "nnfmu.models", "nnfmu.training", "nnfmu.export", "nnfmu.linear",
                  "nnfmu.physics", "nnfmu.greybox", "nnfmu.hybrid", "nnfmu.node", "nnfmu.study", "nnfmu.networks")


def test_every_exported_name_is_on_the_api_page():
    """Each name in ``__all__`` of nnfmu and its subpackages: a ``:::`` block or a row of the constants table."""
    import importlib

    api = (ROOT / "docs" / "api.md").read_text()
    documented = set(re.findall(r"^::: \S*?\.(\w+)$", api, re.M))
    documented |= set(re.findall(r"^\| `nnfmu\.[\w.]*?\.(\w+)` \|", api, re.M))  # the constants
    errors = set(dir(importlib.import_module("nnfmu.errors")))  # `::: nnfmu.errors` renders the whole module
    missing = {(module, name) for module in PUBLIC_MODULES for name in importlib.import_module(module).__all__
               if name not in documented | errors}
    assert missing == set()
    assert {"train_seeds", "load_linear", "slider_system", "sx_to_torch", "tune_architecture",
            "UNBOUNDED_EPOCHS"} <= documented


def test_the_physics_page_lists_every_parameter_with_its_unit_and_default(site):
    import dataclasses

    from nnfmu.physics import ArmParams, SliderParams, ValveParams

    text = (ROOT / "docs" / "physics.md").read_text()
    for params in (ValveParams(), ArmParams(), SliderParams()):
        for f in dataclasses.fields(params):
            value = getattr(params, f.name)
            shown = ", ".join(f"{v:g}" for v in value) if isinstance(value, tuple) else f"{value:g}"
            assert f"| `{f.name}` | {shown} | {f.metadata['unit']} |" in text, (type(params).__name__, f.name)
    assert (site / "physics" / "index.html").is_file()


def test_no_page_requests_external_fonts(site):
    """Material loads Google Fonts unless `font: false`: offline, every page logged errors."""
    for page in site.rglob("*.html"):
        text = page.read_text(encoding="utf-8")
        assert "fonts.googleapis" not in text and "fonts.gstatic" not in text, page


def test_navigation_files_are_not_pages_and_the_notebooks_are(site):
    assert not (site / "cli" / "SUMMARY").exists() and not (site / "notebooks" / "SUMMARY").exists()
    home = (site / "index.html").read_text()
    assert 'href="cli/train/"' in home  # the commands are still in the navigation
    for notebook in sorted((ROOT / "notebooks").glob("*.ipynb")):
        page = site / "notebooks" / notebook.stem / "index.html"
        assert page.is_file(), notebook.name
        assert f'href="notebooks/{notebook.stem}/"' in home
        cells = json.loads(notebook.read_text())["cells"]
        code = [c for c in cells if c["cell_type"] == "code" and "".join(c["source"]).strip()]
        assert page.read_text().count('<div class="highlight">') == len(code), notebook.name  # every code cell


def test_code_blocks_wrap_instead_of_overflowing(site):
    """At 1280 px a long command overflowed its block and hid under the copy button; the site's CSS wraps it."""
    css = (site / "stylesheets" / "extra.css").read_text()
    assert re.search(r"pre > code\s*\{[^}]*white-space:\s*pre-wrap", css)
    assert re.search(r"pre > code\s*\{[^}]*padding-right", css)  # clear of the copy button
    assert 'href="../stylesheets/extra.css"' in (site / "tutorial" / "index.html").read_text()


def test_the_installation_names_every_extra():
    from importlib import metadata

    index = (ROOT / "docs" / "index.md").read_text()
    section = index[index.index("## Installation"):]
    for extra in metadata.metadata("nnfmu").get_all("Provides-Extra"):
        assert f"| `{extra}` |" in section, extra


def test_the_importer_notes_are_documented():
    """fmusim ends a run at the first range Warning; CVode needs an input step as an event (two rows, one time)."""
    fmu = " ".join((ROOT / "docs" / "fmu.md").read_text().split())
    assert "fmusim stops at the first range warning" in fmu
    platforms = " ".join((ROOT / "docs" / "fmu-platforms.md").read_text().split())
    assert "Input steps are events" in platforms and "two rows at the same time" in platforms
