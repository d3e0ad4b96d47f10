"""The ``nnfmu`` command line.

Each sub-command lives in its own module of this package and exposes
``register(subparsers)``, which adds its parser and sets ``func`` (a callable
taking the parsed namespace and returning an exit status). Modules are found
automatically, so adding a command touches no shared file. Command modules
import heavy libraries (torch, casadi) inside ``func`` so that ``nnfmu --help``
stays fast.

The contract of every command (:func:`run`):

- every numeric option is checked against its valid range before the command
  does any work (:mod:`nnfmu.cli._checks`);
- errors of the toolkit (:class:`nnfmu.errors.NnfmuError`) and of the operating
  system (an ``OSError`` such as a read-only folder, a full disk or a path
  through a regular file) print one line, ``nnfmu <command>: error: <message>``,
  and exit with status 2, like argparse's own usage errors; warnings raised
  on the way (torch's, numpy's) are dropped then, and shown at the end otherwise;
- files are written atomically (:mod:`nnfmu.atomic`), so a failed command
  leaves no partial file at its output;
- Ctrl-C exits with 130 and SIGTERM with 143 (128 + the signal number), after
  the same clean-up; a closed output pipe (``nnfmu info D | head -1``) ends quietly with 141, as SIGPIPE
  ends other tools.
"""

from __future__ import annotations

import argparse
import contextlib
import importlib
import os
import pkgutil
import signal
import sys
import threading
import warnings

from nnfmu.atomic import describe_os_error
from nnfmu.cli._checks import check_numbers
from nnfmu.errors import NnfmuError

SIGINT_STATUS, SIGTERM_STATUS = 128 + signal.SIGINT, 128 + signal.SIGTERM
SIGPIPE_STATUS = 128 + 13  # SIGPIPE's number on POSIX (Windows has no signal.SIGPIPE)

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


def run(func, args: argparse.Namespace, prog: str, parser: argparse.ArgumentParser | None = None) -> int:
    """Call a command's ``func``; turn toolkit and OS errors into one line and status 2 (module docstring).

    ``parser`` (the command's own): its numeric options are checked first (:mod:`nnfmu.cli._checks`).
    Warnings (torch's, numpy's) are held back and shown after the command, or dropped when it fails, so that
    a failure is the one error line.
    """
    try:
        with sigterm_as_exception(), warnings.catch_warnings(record=True) as caught:
            if parser is not None:
                check_numbers(parser, args, getattr(args, "command", prog.split()[-1]))
            status = int(func(args) or 0)
        for w in caught:
            warnings.showwarning(w.message, w.category, w.filename, w.lineno)
        return status
    except NnfmuError as exc:
        print(f"{prog}: error: {exc}", file=sys.stderr)
        return 2
    except BrokenPipeError:  # the reader went away (``nnfmu info D | head -1``): end as a killed writer, quietly
        with contextlib.suppress(OSError, ValueError):  # so that the flush at exit is silent too
            os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return SIGPIPE_STATUS
    except OSError as exc:
        print(f"{prog}: error: {describe_os_error(exc)}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"{prog}: interrupted", file=sys.stderr)
        return SIGINT_STATUS
    except Terminated:
        print(f"{prog}: terminated (SIGTERM)", file=sys.stderr)
        return SIGTERM_STATUS


def command_parser(parser: argparse.ArgumentParser, command: str) -> argparse.ArgumentParser:
    """The sub-parser of ``command`` in the ``nnfmu`` parser."""
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    return sub.choices[command]


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    return run(args.func, args, f"nnfmu {args.command}", command_parser(parser, args.command))
