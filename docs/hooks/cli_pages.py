"""Build-time pages (mkdocs-gen-files): one page per nnfmu command, from its argparse parser's own help.

Nothing here is copied by hand: a changed option shows up in the site at the next build.
"""

import argparse
import os

import mkdocs_gen_files
from mkdocs.structure.files import InclusionLevel

from nnfmu.cli import build_parser

os.environ["COLUMNS"] = "100"  # argparse wraps its help to the terminal; the pages use one width
sub = next(a for a in build_parser()._actions if isinstance(a, argparse._SubParsersAction))
summaries = {action.dest: action.help for action in sub._choices_actions}
nav = mkdocs_gen_files.Nav()

with mkdocs_gen_files.open("cli/index.md", "w") as index:
    index.write("# Command line\n\nEvery command prints its help with `--help`; these pages are that help, "
                "generated from the parsers when the site is built. A toolkit error prints one line, "
                "`nnfmu <command>: error: <what is wrong and what to do>`, and exits with status 2.\n\n"
                "| command | what it does |\n| --- | --- |\n")
    for name in sub.choices:
        index.write(f"| [`nnfmu {name}`]({name}.md) | {summaries.get(name, '')} |\n")
nav["Overview"] = "index.md"

for name, parser in sub.choices.items():
    with mkdocs_gen_files.open(f"cli/{name}.md", "w") as page:
        page.write(f"# nnfmu {name}\n\n{summaries.get(name, '')}\n\n```text\n{parser.format_help()}```\n")
    nav[f"nnfmu {name}"] = f"{name}.md"

with mkdocs_gen_files.open("cli/SUMMARY.md", "w") as summary:
    summary.writelines(nav.build_literate_nav())
# the navigation that literate-nav reads, not a page of the site
mkdocs_gen_files.FilesEditor.current().files.get_file_from_path("cli/SUMMARY.md").inclusion = InclusionLevel.EXCLUDED
