"""What the command modules share."""

from __future__ import annotations

import argparse
from typing import Protocol

__all__ = ["EPILOG", "Subparsers"]

EPILOG = (
    "Data: a SOURCE is a directory in the marina layout (see README) or the named source 'marina', "
    "found under $SONARSLAM_DATA/marina."
)


class Subparsers(Protocol):
    """``argparse``'s sub-parser action (its ``add_parser``)."""

    def add_parser(self, name: str, **kwargs: object) -> argparse.ArgumentParser: ...
