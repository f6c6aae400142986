"""The ``sonarslam`` command: builds the parser from :mod:`sonarslam.slam.cli.parsers` (light:
``--version`` and every ``--help`` answer without importing the library), imports the module of
the one command that runs, and turns every known error into one line on stderr, no traceback:
exit 2 for usage (a wrong option, a setting that does not fit its field, an ``--out`` that
cannot be written), exit 1 for data (:class:`sonarslam.datasets.errors.DataError` naming the
file and line, other input that cannot be run, a file that cannot be written) and for an
optional dependency that is not installed (:class:`~sonarslam.datasets.errors.MissingExtraError`
naming the extra)."""

from __future__ import annotations

import argparse
import importlib
import sys
import warnings
from collections.abc import Sequence
from importlib.metadata import PackageNotFoundError, version
from typing import cast

from sonarslam.datasets.errors import DataError, DataWarning, MissingExtraError
from sonarslam.settings import SettingError
from sonarslam.slam.cli.common import EPILOG, Parser, Subparsers
from sonarslam.slam.cli.parsers import COMMANDS

__all__ = ["main", "build_parser"]


def _version() -> str:
    try:
        return version("sonarslam")
    except PackageNotFoundError:  # run from a source tree that was not installed
        return "unknown (not installed)"


def build_parser() -> argparse.ArgumentParser:
    return _parsers()[0]


def _parsers() -> tuple[argparse.ArgumentParser, dict[str, argparse.ArgumentParser]]:
    """The ``sonarslam`` parser, and each command's own parser by its name."""
    parser = Parser(
        prog="sonarslam",
        description="Line features with honest uncertainty from MSIS sonar, and SLAM with them.",
        epilog=EPILOG,
    )
    parser.add_argument("--version", action="version", version=f"sonarslam {_version()}")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    commands: dict[str, argparse.ArgumentParser] = {}
    for name, add_parser, module in COMMANDS:
        commands[name] = add_parser(cast(Subparsers, sub))
        commands[name].set_defaults(implementation=module)
    return parser, commands


def main(argv: Sequence[str] | None = None) -> int:
    parser, commands = _parsers()
    args, unknown = parser.parse_known_args(argv)
    if unknown:  # argparse says these as the top-level parser's; the command's own says them
        commands[args.command].error(f"unrecognized arguments: {' '.join(unknown)}")
    with warnings.catch_warnings():
        warnings.simplefilter("always", DataWarning)
        warnings.showwarning = _OnceEach()
        try:
            # the command's module, and with it the library, only now (parsers.COMMANDS)
            return int(importlib.import_module(args.implementation).command(args))
        except SettingError as exc:
            print(f"sonarslam {args.command}: error: {exc}", file=sys.stderr)
            return 2
        except (DataError, ValueError, MissingExtraError) as exc:
            print(f"sonarslam {args.command}: error: {_one_line(exc)}", file=sys.stderr)
            return 1
        except OSError as exc:  # writing the outputs: disk full, permissions
            where = f"{exc.filename}: " if exc.filename else ""
            print(f"sonarslam {args.command}: error: {where}{exc.strerror or exc}", file=sys.stderr)
            return 1


class _OnceEach:
    """``warnings.showwarning`` of a command: a warning as one line on stderr, ``warning:
    <message>``, each message once (a command that opens its dataset for several runs would
    print the same data warning for each)."""

    def __init__(self) -> None:
        self.shown: set[str] = set()

    def __call__(
        self,
        message: Warning | str,
        category: type[Warning],
        filename: str,
        lineno: int,
        file: object = None,
        line: str | None = None,
    ) -> None:
        text = " ".join(str(message).split())
        if text not in self.shown:
            self.shown.add(text)
            print(f"warning: {text}", file=sys.stderr)


def _one_line(exc: Exception) -> str:
    """The message on one line (a TOML syntax error's own text has several)."""
    return " ".join(str(exc).split())


if __name__ == "__main__":
    raise SystemExit(main())
