"""The ``sonarslam`` command: builds the parser from the command modules, runs one, and turns
known errors into one line (exit 1) and usage errors into argparse's (exit 2)."""

from __future__ import annotations

import argparse
import sys
import warnings
from collections.abc import Sequence
from importlib.metadata import PackageNotFoundError, version

from datasets.errors import DataError, DataWarning
from slam.cli import calibrate, demo, extract, info, plot_scans, report, run, simulate, sweep
from slam.cli.common import EPILOG

__all__ = ["main", "build_parser"]

#: The command modules, in ``--help`` order; each has ``add_parser`` and ``command``.
COMMANDS = (simulate, run, plot_scans, extract, demo, calibrate, info, report, sweep)


def _version() -> str:
    try:
        return version("sonarslam")
    except PackageNotFoundError:  # run from a source tree that was not installed
        return "unknown (not installed)"


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="sonarslam",
        description="Line features with honest uncertainty from MSIS sonar, and SLAM with them.",
        epilog=EPILOG,
    )
    parser.add_argument("--version", action="version", version=f"sonarslam {_version()}")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for module in COMMANDS:
        module.add_parser(sub)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    with warnings.catch_warnings():
        warnings.simplefilter("always", DataWarning)
        warnings.formatwarning = lambda msg, *a, **k: f"warning: {msg}\n"  # type: ignore[assignment]
        try:
            return int(args.func(args))
        except (DataError, ValueError, FileNotFoundError) as exc:
            print(f"sonarslam {args.command}: error: {exc}", file=sys.stderr)
            return 1


if __name__ == "__main__":
    raise SystemExit(main())
