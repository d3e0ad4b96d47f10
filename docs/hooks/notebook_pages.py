"""Build-time pages (mkdocs-gen-files): one page per notebook in notebooks/, read from the .ipynb itself.

The notebooks are committed without outputs (tests/test_notebooks.py), so a page is their Markdown cells
and their code cells as Python blocks, in order; nothing is executed and nothing but the standard library
reads them. Run a notebook with Jupyter to see its output.
"""

import json
from pathlib import Path

import mkdocs_gen_files
from mkdocs.structure.files import InclusionLevel

ROOT = Path(__file__).resolve().parent.parent.parent
NOTEBOOKS = sorted((ROOT / "notebooks").glob("*.ipynb"))


def _text(cell) -> str:
    source = cell.get("source", "")
    return "".join(source) if isinstance(source, list) else source


def notebook_markdown(path: Path) -> str:
    """The page of one notebook: a note on where it is, then its cells."""
    book = json.loads(path.read_text(encoding="utf-8"))
    parts = []
    for cell in book["cells"]:
        text = _text(cell).strip("\n")
        if cell["cell_type"] == "markdown":
            parts.append(text)
        elif cell["cell_type"] == "code" and text:
            parts.append(f"```python\n{text}\n```")
    head, rest = (parts[0], parts[1:]) if parts and parts[0].startswith("# ") else (f"# {path.stem}", parts)
    note = (f"!!! note \"Notebook `notebooks/{path.name}`\"\n    This page is the notebook as committed, without "
            f"outputs. Run it with `jupyter lab notebooks/{path.name}` (the extra `notebooks`); it runs top to "
            f"bottom on small default settings and ends with its own checks.")
    return "\n\n".join([head, note, *rest]) + "\n"


nav = mkdocs_gen_files.Nav()
with mkdocs_gen_files.open("notebooks/index.md", "w") as index:
    index.write("# Notebooks\n\nThe notebooks in `notebooks/`, one page each (without outputs):\n\n")
    for path in NOTEBOOKS:
        title = notebook_markdown(path).splitlines()[0].lstrip("# ").strip()
        index.write(f"- [{title}]({path.stem}.md)\n")
nav["Overview"] = "index.md"
for path in NOTEBOOKS:
    with mkdocs_gen_files.open(f"notebooks/{path.stem}.md", "w") as page:
        page.write(notebook_markdown(path))
    nav[path.stem] = f"{path.stem}.md"
with mkdocs_gen_files.open("notebooks/SUMMARY.md", "w") as summary:
    summary.writelines(nav.build_literate_nav())
# the navigation that literate-nav reads, not a page of the site
mkdocs_gen_files.FilesEditor.current().files.get_file_from_path("notebooks/SUMMARY.md").inclusion = InclusionLevel.EXCLUDED
