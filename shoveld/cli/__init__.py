"""The ``shoveld`` command: one program, subcommands registered by module.

Each subcommand lives in its own module under ``shoveld.cli`` exposing
``register(subparsers)``; listing it in ``SUBCOMMANDS`` is all it takes to add one.
Heavy imports happen inside the command functions so ``--help`` stays fast.
"""

from __future__ import annotations

import argparse
import importlib
import logging
import os
import sys
from collections.abc import Sequence
from typing import Any, NoReturn

SUBCOMMANDS: tuple[str, ...] = (
    "sim", "calibrate", "estimate", "diagnose", "decode", "record", "replay", "run",
    "cab", "office", "passes", "report", "check_config", "demo", "pki",
)


class CliError(Exception):
    """An error to print as one line and exit with status 2."""


def _version() -> str:
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("shoveld")
    except PackageNotFoundError:
        return "(not installed)"


class _Version(argparse._VersionAction):
    """``--version``, with the version looked up only when asked: the package metadata
    costs 14 ms of every command's start otherwise."""

    def __call__(self, parser: argparse.ArgumentParser, namespace: argparse.Namespace,
                 values: str | Sequence[Any] | None, option_string: str | None = None) -> None:
        self.version = f"shoveld {_version()}"
        super().__call__(parser, namespace, values, option_string)


class _Help(argparse.HelpFormatter):
    """``--help`` shows each option's default, where it has one worth saying and its
    text does not say it already."""

    def _get_help_string(self, action: argparse.Action) -> str | None:
        text = action.help or ""
        d = action.default
        if (action.option_strings and d is not None and d is not False and d != []
                and d is not argparse.SUPPRESS
                and "default" not in text and "%(default)" not in text
                and not isinstance(action, argparse._VersionAction)):
            text += " (default: %(default)s)"
        return text


def _named_command(argv: list[str]) -> str | None:
    """The subcommand module ``argv`` names, if its first word after the global options
    is one: the global options (``-v``, ``--version``, ``-h``) take no value, so that
    word is the command. None when there is none or it is not a subcommand."""
    for word in argv:
        if word == "--":
            return None
        if not word.startswith("-"):
            name = word.replace("-", "_")
            return name if name in SUBCOMMANDS else None
    return None


def build_parser(only: str | None = None) -> argparse.ArgumentParser:
    """The whole command line; with ``only`` (a name in ``SUBCOMMANDS``), just that
    subcommand: importing every subcommand's module (argument types, choices, their
    own imports) was 30-60 ms of every command's start, and a command line that names
    its subcommand parses the same with the others absent. ``--help``, a missing or an
    unknown command get the full parser (its list of commands and its error)."""
    p = argparse.ArgumentParser(
        prog="shoveld",
        description="Onboard payload monitor for electric cable (rope) mining shovels.")
    p.add_argument("-v", "--verbose", action="count", default=0, help="more log output")
    p.add_argument("--version", action=_Version, help="show the version and exit")
    sub = p.add_subparsers(dest="command", metavar="COMMAND", required=True)
    add = sub.add_parser

    def add_parser(name: str, **kw: object) -> argparse.ArgumentParser:
        kw.setdefault("formatter_class", _Help)
        return add(name, **kw)  # type: ignore[arg-type]
    sub.add_parser = add_parser  # type: ignore[method-assign]
    for name in SUBCOMMANDS if only is None else (only,):
        try:
            mod = importlib.import_module(f"shoveld.cli.{name}")
        except ModuleNotFoundError as e:
            if e.name == f"shoveld.cli.{name}":
                continue  # subcommand not built yet
            raise
        mod.register(sub)
    return p


def _exit_at_once(code: int) -> NoReturn:
    """End the process now, with ``code``, once stdout, stderr and the log are flushed.

    For a command that has closed and removed everything it opened (``replay``: the
    pass log, the Zenoh session, its temporary folder): the interpreter's own shutdown
    would only collect and free what the run left - the capture's recording, the
    engine's state, some 55,000 tracked objects - and tear down numpy and Zenoh, 30-60
    ms of a 0.45 s ``shoveld replay --fast`` on this machine."""
    logging.shutdown()
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except (OSError, ValueError):  # a closed pipe, a closed stream: nothing to keep
            pass
    os._exit(code)


def main(argv: list[str] | None = None) -> int:
    """Run the command line ``argv`` (default: this program's arguments). Called as the
    program (no ``argv``), a command that says it leaves nothing to shut down
    (``exit_at_once`` in its defaults) ends the process when it returns."""
    program = argv is None
    if argv is None:
        argv = sys.argv[1:]
    parser = build_parser(_named_command(argv))
    args = parser.parse_args(argv)
    level = logging.WARNING - 10 * min(args.verbose, 2)
    logging.basicConfig(level=level, format="%(levelname)s %(name)s: %(message)s",
                        stream=sys.stderr)
    try:
        code = int(args.func(args) or 0)
        if program and getattr(args, "exit_at_once", False):
            _exit_at_once(code)
        return code
    except CliError as e:
        print(f"shoveld {args.command}: error: {e}", file=sys.stderr)
        return 2
    except BrokenPipeError:
        return 0
    except OSError as e:
        # A file the command was told to read or write is missing, in a folder that is
        # not there, or not permitted: the user's to fix, so one line naming it. An
        # OSError without a file name is not that, and keeps its traceback.
        if e.filename is None:
            raise
        hint = ""
        parent = os.path.dirname(os.fspath(e.filename)) or "."
        if isinstance(e, FileNotFoundError) and not os.path.isdir(parent):
            hint = f" (the folder {parent} does not exist)"
        print(f"shoveld {args.command}: error: {e.filename}: {e.strerror}{hint}",
              file=sys.stderr)
        return 2
