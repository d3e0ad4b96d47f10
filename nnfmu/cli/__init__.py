"""The ``nnfmu`` command line.

Each sub-command lives in its own module of this package and exposes
``register(subparsers)``, which adds its parser and sets ``func`` (a callable
taking the parsed namespace and returning an exit status). Modules are found
automatically, so adding a command touches no shared file. Command modules
import heavy libraries (torch, casadi) inside ``func`` so that ``nnfmu --help``
stays fast.

The contract of every command (:func:`run`):

- errors of the toolkit (:class:`nnfmu.errors.NnfmuError`) and of the operating
  system (an ``OSError`` such as a read-only folder, a full disk or a path
  through a regular file) print one line, ``nnfmu <command>: error: <message>``,
  and exit with status 2, like argparse's own usage errors;
- files are written atomically (:mod:`nnfmu.atomic`), so a failed command
  leaves no partial file at its output;
- Ctrl-C exits with 130 and SIGTERM with 143 (128 + the signal number), after
  the same clean-up.
"""

from __future__ import annotations

import argparse
import contextlib
import importlib
import pkgutil
import signal
import sys
import threading

from nnfmu.atomic import describe_os_error
from nnfmu.errors import NnfmuError

SIGINT_STATUS, SIGTERM_STATUS = 128 + signal.SIGINT, 128 + signal.SIGTERM

class Terminated(BaseException):
    """Raised in the main thread when SIGTERM arrives, so that writers clean up like on Ctrl-C."""


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


def _raise_terminated(signum, frame) -> None:
    raise Terminated


@contextlib.contextmanager
def sigterm_as_exception():
    """While active (main thread only), SIGTERM raises :class:`Terminated` instead of killing the process."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = signal.signal(signal.SIGTERM, _raise_terminated)
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, previous)


def run(func, args: argparse.Namespace, prog: str) -> int:
    """Call a command's ``func``; turn toolkit and OS errors into one line and status 2 (module docstring)."""
    try:
        with sigterm_as_exception():
            return int(func(args) or 0)
    except NnfmuError as exc:
        print(f"{prog}: error: {exc}", file=sys.stderr)
        return 2
    except OSError as exc:
        print(f"{prog}: error: {describe_os_error(exc)}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"{prog}: interrupted", file=sys.stderr)
        return SIGINT_STATUS
    except Terminated:
        print(f"{prog}: terminated (SIGTERM)", file=sys.stderr)
        return SIGTERM_STATUS


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    return run(args.func, args, f"nnfmu {args.command}")
