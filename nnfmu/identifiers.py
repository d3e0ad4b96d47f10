"""What a name that reaches C must look like: one check and one repair, ASCII only.

Model names become the FMU's ``modelIdentifier`` (C symbol prefixes, file names) and
variable and channel names become FMU variable names and C strings, so nnfmu holds them
to C's identifier rule ``[A-Za-z_][A-Za-z0-9_]*``. :meth:`str.isidentifier` is not that
rule: it accepts non-ASCII letters (``"Düse"``), which C compilers and FMU importers
do not all take.
"""

from __future__ import annotations

import re

__all__ = ["C_IDENTIFIER", "is_c_identifier", "to_c_identifier"]

#: C's identifier rule, ASCII letters, digits and underscores, not starting with a digit.
C_IDENTIFIER = re.compile(r"[A-Za-z_][A-Za-z0-9_]*")


def is_c_identifier(name) -> bool:
    """Whether ``name`` is a string that C takes as an identifier (``"valve_2"`` yes; ``"2x"``, ``"Düse"`` no)."""
    return isinstance(name, str) and C_IDENTIFIER.fullmatch(name) is not None


def to_c_identifier(text: str, prefix: str = "m_") -> str:
    """``text`` made a C identifier: every run of other characters becomes ``_`` (ends stripped), and
    ``prefix`` goes in front of a name that would start with a digit or be empty (``"2 tanks"`` -> ``"m_2_tanks"``)."""
    name = re.sub(r"[^A-Za-z0-9_]+", "_", str(text)).strip("_")
    return name if name[:1].isalpha() else f"{prefix}{name}"
