"""What the command modules share."""

from __future__ import annotations

import argparse
from typing import Protocol

from slam.run.sources import POSE_SOURCES

__all__ = ["EPILOG", "Subparsers", "add_source", "add_poses", "add_quiet"]

EPILOG = (
    "Data: a SOURCE is a directory in the marina layout (see README) or the named source 'marina', "
    "found under $SONARSLAM_DATA/marina."
)


class Subparsers(Protocol):
    """``argparse``'s sub-parser action (its ``add_parser``)."""

    def add_parser(self, name: str, **kwargs: object) -> argparse.ArgumentParser: ...


def add_source(p: argparse.ArgumentParser) -> None:
    """The positional SOURCE of a command that reads a dataset."""
    p.add_argument("source", help="dataset directory or 'marina'")


def add_poses(p: argparse.ArgumentParser, default: str, note: str = "") -> None:
    """``--poses``: one of :data:`slam.run.sources.POSE_SOURCES`."""
    p.add_argument(
        "--poses",
        default=default,
        choices=sorted(POSE_SOURCES),
        help=f"pose source: gps (GPS+AHRS), dr (dead reckoning), truth (simulated only);"
        f" default {default}{note}",
    )


def add_quiet(p: argparse.ArgumentParser) -> None:
    """``--quiet``: no progress bars."""
    p.add_argument("--quiet", action="store_true", help="no progress bars")
