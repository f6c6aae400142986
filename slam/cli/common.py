"""What the command modules share."""

from __future__ import annotations

import argparse
import math
from collections.abc import Callable
from typing import NoReturn, Protocol

from sonarslam.settings import SettingError, coerce

__all__ = [
    "EPILOG",
    "Parser",
    "Subparsers",
    "add_source",
    "add_poses",
    "add_quiet",
    "add_start",
    "parse_start",
    "poses_for",
    "number",
    "POSES",
]

#: ``--poses``: :data:`sonarslam.slam.run.sources.POSE_SOURCES`, sorted (spelled out so that the
#: parsers import nothing of the library; ``tests/test_cli.py`` checks they are the same).
POSES = ("dr", "gps", "truth")


class Parser(argparse.ArgumentParser):
    """argparse's parser whose usage errors are one line (exit 2), as every known error of
    the command line is."""

    def error(self, message: str) -> NoReturn:
        self.exit(2, f"{self.prog}: error: {message} (see {self.prog} --help)\n")


def number(
    kind: type, low: float | None = None, high: float | None = None, low_open: bool = False
) -> Callable[[str], float | int]:
    """An argparse ``type``: a finite ``float`` or a whole ``int`` (:mod:`sonarslam.settings`'s
    grammar: no ``nan``, ``inf``, ``1_0``) within ``[low, high]`` (``(low, ...`` when
    ``low_open``)."""

    def parse(text: str) -> float | int:
        try:
            value = coerce(kind, text, "value")
        except SettingError as exc:
            raise argparse.ArgumentTypeError(f"{exc.message}") from None
        below = low is not None and (value <= low if low_open else value < low)
        if below or (high is not None and value > high) or not math.isfinite(value):
            lo = "" if low is None else f"{'>' if low_open else '>='} {low:g}"
            hi = "" if high is None else f"<= {high:g}"
            raise argparse.ArgumentTypeError(
                f"must be {' and '.join(x for x in (lo, hi) if x)}, got {text!r}"
            )
        return value  # type: ignore[no-any-return]

    parse.__name__ = kind.__name__  # argparse names the type in its message
    return parse


EPILOG = (
    "Data: a SOURCE is a directory in the marina layout, a ROS 1 or ROS 2 bag, a Ping Viewer .bin"
    " log with its navigation (docs/data.md) or the named source 'marina', found under"
    " $SONARSLAM_DATA/marina."
)


class Subparsers(Protocol):
    """``argparse``'s sub-parser action (its ``add_parser``)."""

    def add_parser(self, name: str, **kwargs: object) -> argparse.ArgumentParser: ...


def add_source(p: argparse.ArgumentParser, loop: bool = False) -> None:
    """The positional SOURCE of a command that reads a dataset, with ``--nav`` and ``--span``
    (``loop``: the command takes ``--loop`` too, whose times then count from the span's T0)."""
    p.add_argument(
        "source",
        help="dataset directory, ROS bag (.bag, .mcap, ROS 2 bag directory), Ping Viewer .bin"
        " or 'marina'",
    )
    p.add_argument(
        "--nav",
        metavar="FILE",
        action="append",
        help="a Ping Viewer .bin's navigation: a ROS bag (DVL, IMU, GPS topics), a CSV, or a"
        " BlueROV2's own logs told by their content (a QGroundControl .tlog or CSV export, an"
        " ArduSub dataflash .bin, a Water Linked DVL A50 JSON log); repeat it to take the DVL"
        " from one and the heading from another (docs/data.md; default: [ping360] nav of the"
        " sonarslam.toml beside the .bin; without either, the .bin alone is read as a still"
        " head at --start)",
    )
    p.add_argument(
        "--span",
        type=parse_loop,
        default=None,
        metavar="T0,T1",
        help="take the part of the source from T0 to T1 (s from the start of the navigation, as"
        " info's segments; a .bin without navigation: from its first beam): its beams,"
        " navigation and GPS" + ("; --loop times then count from T0" if loop else ""),
    )


def add_topics(p: argparse.ArgumentParser) -> None:
    """``--topics``: which topic of a bag plays which role."""
    p.add_argument(
        "--topics",
        metavar="TOML",
        help="a bag's roles: [topics] sonar, dvl, imu, gps = topic names, or a preset's name"
        " (caves); default: by message type, [topics] of the bag's sonarslam.toml, or the preset"
        " whose topics the bag has",
    )


def add_config_and_set(p: argparse.ArgumentParser) -> None:
    """``--config`` (a ``sonarslam.toml`` over the dataset's) and ``--set`` (run settings), as
    ``run`` takes them and ``info`` lists them."""
    p.add_argument(
        "--config",
        default=None,
        help="a sonarslam.toml-format file whose keys replace the dataset's calibration"
        " (e.g. [mounting.ahrs] yaw_deg); the one used is written to OUT/config_used.toml",
    )
    p.add_argument(
        "--set",
        action="append",
        default=[],
        metavar="SCOPE.FIELD=VALUE",
        help="an extractor or back-end setting, repeatable: extractor.max_range_m=25,"
        " ekf.extent_margin_m=10, isam2.robust=cauchy, isam2.association=nn (fields of"
        " ExtractorConfig, EkfConfig, GraphConfig); recorded in metrics.json",
    )


def add_poses(p: argparse.ArgumentParser, default: str | None, note: str = "") -> None:
    """``--poses``: one of :data:`POSES`; a ``default`` of None is :func:`poses_for`'s."""
    said = default or "gps (a .bin without navigation: dr, its still head)"
    p.add_argument(
        "--poses",
        default=default,
        choices=POSES,
        help=f"pose source: gps (GPS+AHRS), dr (dead reckoning), truth (simulated only);"
        f" default {said}{note}",
    )


def poses_for(poses: str | None, still: bool) -> str:
    """``--poses`` as given, else ``gps``; of a still head (a ``.bin`` without navigation, no
    GPS either) ``dr``, its pose."""
    return poses if poses is not None else "dr" if still else "gps"


def add_quiet(p: argparse.ArgumentParser, progress: bool = True) -> None:
    """``--quiet``: no progress bars; every command takes it (``progress``: the command draws
    any; one that draws none accepts it and says so)."""
    p.add_argument(
        "--quiet",
        action="store_true",
        help="no progress bars (warnings are still printed)"
        if progress
        else "accepted as by every command; this one draws no progress bars, so it changes"
        " nothing (warnings are still printed)",
    )


def parse_start(text: str) -> tuple[float, float, float]:
    """``X,Y`` or ``X,Y,YAW`` (m, m, deg CCW from East) to ``(x_m, y_m, yaw_rad)`` (yaw NaN
    when left out); an argparse ``type``."""
    parts = text.split(",")
    if len(parts) not in (2, 3):
        raise argparse.ArgumentTypeError(f"must be X,Y or X,Y,YAW (m, m, deg), got {text!r}")
    values = [float(number(float)(v.strip())) for v in parts]
    yaw = math.radians(values[2]) if len(values) == 3 else math.nan
    return values[0], values[1], yaw


#: A ``--loop`` time this large (s, ~3 years) is a Unix time, not one from the start.
UNIX_TIME_S = 1e8


def parse_loop(text: str) -> tuple[float, float]:
    """``T0,T1`` (s from the start of the navigation, ``0 <= T0 < T1``); an argparse ``type``
    (``--loop``, ``--span``)."""
    parts = text.split(",")
    if len(parts) != 2:
        raise argparse.ArgumentTypeError(f"must be T0,T1 (s from the start), got {text!r}")
    said = "T0,T1 are seconds from the start of the navigation, not Unix times"
    try:
        t0, t1 = (float(number(float)(v.strip())) for v in parts)
    except argparse.ArgumentTypeError as exc:
        raise argparse.ArgumentTypeError(f"{said}: {exc}") from None
    if max(abs(t0), abs(t1)) >= UNIX_TIME_S:
        raise argparse.ArgumentTypeError(f"{said} (sonarslam info gives the span), got {text!r}")
    if not 0.0 <= t0 < t1:
        raise argparse.ArgumentTypeError(f"must have 0 <= T0 < T1, got {text!r}")
    return t0, t1


def add_start(p: argparse.ArgumentParser) -> None:
    """``--start X,Y[,YAW]``: the start position a user gives (runs without GPS start at the
    origin); the heading is always the AHRS's, a YAW given is checked against it."""
    p.add_argument(
        "--start",
        type=parse_start,
        default=None,
        metavar="X,Y[,YAW]",
        help="start position in the local East-North frame (m); default: the first GPS fix, or"
        " without GPS the origin. The heading is the AHRS's: a YAW given (deg CCW from East) must"
        " agree with it within 3 [noise] ahrs_sigma_deg. A .bin without navigation: the still"
        " head's pose, the whole log long (YAW default 0: East)",
    )
