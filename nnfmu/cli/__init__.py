"""The ``nnfmu`` command line.

Each sub-command lives in its own module of this package and exposes
``register(subparsers)``, which adds its parser and sets ``func`` (a callable
taking the parsed namespace and returning an exit status). Modules are found
automatically, so adding a command touches no shared file. Command modules
import heavy libraries (torch, casadi) inside ``func`` so that ``nnfmu --help``
stays fast.

Errors of the toolkit (:class:`nnfmu.errors.NnfmuError`) print one line,
``nnfmu <command>: error: <message>``, and exit with status 2, like argparse's
own usage errors.
"""

from __future__ import annotations

import argparse
import importlib
import pkgutil
import sys

from nnfmu.errors import NnfmuError


class OneLineErrorParser(argparse.ArgumentParser):
    """An ArgumentParser whose usage errors are one line: ``prog: error: msg (see --help)``."""

    def error(self, message: str):  # noqa: D401 - argparse API
        self.exit(2, f"{self.prog}: error: {message} (see '{self.prog} --help')\n")


def build_parser() -> argparse.ArgumentParser:
    parser = OneLineErrorParser(
        prog="nnfmu",
        description="Train neural simulation models of dynamical systems and export them as FMUs.",
    )
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True,
                                parser_class=OneLineErrorParser)
    for info in sorted(pkgutil.iter_modules(__path__), key=lambda m: m.name):
        if info.name.startswith("_"):
            continue
        module = importlib.import_module(f"{__name__}.{info.name}")
        module.register(sub)
    return parser


def run(func, args: argparse.Namespace, prog: str) -> int:
    """Call a command's ``func``; turn toolkit errors into one line and status 2."""
    try:
        return int(func(args) or 0)
    except NnfmuError as exc:
        print(f"{prog}: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"{prog}: interrupted", file=sys.stderr)
        return 130


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    return run(args.func, args, f"nnfmu {args.command}")
