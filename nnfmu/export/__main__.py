"""``python -m nnfmu.export model.pt -o model.fmu [--fmi-version 2|3] [--name NAME]``.

Loads a trained checkpoint, turns the network into CasADi ``(init, step)``
functions and writes a standalone-C co-simulation FMU. Toolkit errors print
one line and exit with status 2 (the same as ``nnfmu export``).
"""

from __future__ import annotations

import sys

from nnfmu.cli import OneLineErrorParser, run
from nnfmu.cli.export import add_arguments, export_checkpoint

PROG = "python -m nnfmu.export"


def main(argv: list[str] | None = None) -> int:
    parser = OneLineErrorParser(prog=PROG, description="Export a trained nnfmu network as a standalone FMU.")
    add_arguments(parser)
    args = parser.parse_args(argv)
    return run(export_checkpoint, args, PROG)


if __name__ == "__main__":
    sys.exit(main())
