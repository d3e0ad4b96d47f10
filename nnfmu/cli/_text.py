"""Help texts from docstrings, as plain text: ``--help`` is read in a terminal, not rendered as reST."""

from __future__ import annotations

import re

_ROLE = re.compile(r":[a-z]+:`~?([^`]+)`")  # :mod:`nnfmu.study.budgets` -> nnfmu.study.budgets
_LITERAL = re.compile(r"``([^`]+)``")         # ``--grid`` -> --grid


def plain(text: str) -> str:
    """``text`` without reStructuredText roles and literals, its lines joined into one paragraph."""
    text = _LITERAL.sub(r"\1", _ROLE.sub(r"\1", text))
    return " ".join(text.split())


def description(doc: str) -> str:
    """A command's ``--help`` description: its module docstring after the first paragraph, as plain text."""
    return plain(doc.split("\n\n", 1)[1])
