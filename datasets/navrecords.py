"""What a navigation log of a BlueROV2-class vehicle holds, whatever wrote it: the common
records of :mod:`sonarslam.datasets.mavlink` (QGroundControl ``.tlog``, ArduSub dataflash),
:mod:`sonarslam.datasets.dvljson` (the Water Linked DVL A50's JSON) and
:mod:`sonarslam.datasets.qgccsv` (QGroundControl's CSV export); :mod:`sonarslam.datasets.navlog`
picks the odometry and the heading among them.

Frames and units are fixed in the readers, as everywhere (:mod:`sonarslam.datasets.records`):
times Unix s, headings counter-clockwise from East (rad; a NED heading ``psi`` is
``pi/2 - psi``, converted once, in the reader), a DVL's velocities in its own frame with y to
the left (a forward-right-down frame's y is negated in the reader), an autopilot's velocity
estimate in local East-North (m/s).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from datetime import UTC, datetime, timedelta, timezone
from pathlib import Path

import numpy as np

from sonarslam.datasets.errors import DataError
from sonarslam.datasets.records import AttitudeSeries, DvlSeries, GpsSeries
from sonarslam.features.geometry import FloatArray
from sonarslam.settings import bounded, check_fields, one_of

__all__ = [
    "NavLogSettings",
    "Stream",
    "WorldVelocity",
    "NavLog",
    "stream_of",
    "unix_s_of_iso",
    "EARLIEST_UNIX_S",
    "LATEST_UNIX_S",
]

#: A time stamp before the year 2000 or after 2100 (Unix s) is not a wall clock's: a clock
#: counting from a device's boot (an A50 without NTP, an autopilot without GPS time).
EARLIEST_UNIX_S = 946_684_800.0
LATEST_UNIX_S = 4_102_444_800.0
ODOMETRY_CHOICES = ("auto", "dvl", "autopilot")


@dataclass(frozen=True)
class NavLogSettings:
    """The ``[navlog]`` table of ``sonarslam.toml``: how to read a navigation log.

    Attributes
    ----------
    start : str
        An ISO 8601 date and time (``2024-05-02T10:31:07.250+02:00``; without an offset,
        ``utc_offset_h`` applies) of the log's first record, for a log whose clock is not a
        wall clock: the A50's ``json_v1`` (its ``time`` is ms since the report before), an
        A50 without NTP (its clock counts from its boot), a dataflash log without GPS time
        (``TimeUS`` counts from the autopilot's boot). "" none.
    utc_offset_h : float
        The logging computer's clock is UTC plus this (h): QGroundControl's CSV stamps its
        rows in the computer's local time.
    odometry : str
        ``"auto"`` (the DVL's own velocities where the logs hold them, else the autopilot's
        velocity estimate), ``"dvl"`` (the DVL's own: an error without them) or
        ``"autopilot"`` (the autopilot's estimate, even beside the DVL's own).
    """

    start: str = ""
    utc_offset_h: float = bounded(0.0, -14.0, 14.0)
    odometry: str = one_of("auto", *ODOMETRY_CHOICES)

    def __post_init__(self) -> None:
        check_fields(self)


@dataclass(frozen=True)
class Stream:
    """One stream of a navigation log (a MAVLink message type, a dataflash message, a JSON
    report type, a CSV column group), for ``sonarslam info``.

    Attributes
    ----------
    name : str
        ``ATTITUDE``, ``VISO``, ``velocity``, ``heading``...
    count : int
        Records read.
    t_first_s, t_last_s : float
        Its first and last time (Unix s; NaN without a clock).
    rate_hz : float
        Records per second over its span (0 with fewer than two).
    gaps : int
        Silences longer than five median periods and a second (the gates' default).
    longest_gap_s : float
    use : str
        What sonarslam takes it for ("odometry", "heading", "ruler", ""), and why not where it
        is left.
    """

    name: str
    count: int
    t_first_s: float
    t_last_s: float
    rate_hz: float
    gaps: int = 0
    longest_gap_s: float = 0.0
    use: str = ""


#: A gap: no record for this many median periods, and at least this long (s): the defaults of
#: ``[gates]`` (:class:`sonarslam.datasets.config.GateConfig`).
GAP_PERIODS = 5.0
MIN_GAP_S = 1.0


def stream_of(name: str, t_s: FloatArray, use: str = "") -> Stream:
    """A :class:`Stream` of the record times ``t_s`` (Unix s, any order)."""
    t = np.sort(np.asarray(t_s, dtype=np.float64))
    if not t.size:
        return Stream(name, 0, math.nan, math.nan, 0.0, 0, 0.0, use)
    span = float(t[-1] - t[0])
    rate = (t.size - 1) / span if span > 0 else 0.0
    steps = np.diff(t)
    gaps, longest = 0, 0.0
    if steps.size:
        positive = steps[steps > 0]
        period = float(np.median(positive)) if positive.size else 0.0
        long_ = steps[steps > max(GAP_PERIODS * period, MIN_GAP_S)]
        gaps, longest = int(long_.size), float(long_.max(initial=0.0))
    return Stream(name, int(t.size), float(t[0]), float(t[-1]), rate, gaps, longest, use)


@dataclass(frozen=True)
class WorldVelocity:
    """An autopilot's own velocity estimate over ground (m/s, local East-North): not a
    measurement but the output of its filter, which fuses whatever it has (a DVL, a GPS).

    Attributes
    ----------
    t : ndarray, shape (N,)
        Unix s.
    v_en_mps : ndarray, shape (N, 2)
        East and North velocity (m/s).
    path : Path
    resolution_mps : float
        The quantum the log rounds the velocity to (m/s; 0: not rounded).
    """

    t: FloatArray
    v_en_mps: FloatArray
    path: Path
    resolution_mps: float = 0.0


@dataclass(frozen=True)
class NavLog:
    """A navigation log, read (:func:`sonarslam.datasets.navlog.read_nav_log`).

    Attributes
    ----------
    path : Path
    kind : str
        What wrote it, in words ("QGroundControl telemetry log (.tlog)").
    streams : tuple of Stream
        Every stream it holds, for ``sonarslam info``.
    dvl : DvlSeries or None
        The DVL's own velocities in its frame (x forward, y left; m/s): its reports, or the
        deltas it sent the autopilot (``VISION_POSITION_DELTA``, ``VISO``) over their time.
    dvl_source : str
        Which stream gave ``dvl``, in words.
    autopilot : WorldVelocity or None
        The autopilot's velocity estimate.
    autopilot_source : str
    attitude : AttitudeSeries or None
        The heading of the AHRS frame (rad, CCW from East) and its rate (rad/s, CCW).
    heading_source : str
    heading_absolute : bool
        The heading is referred to North (a compass in the loop); False for a heading relative
        to where the sensor started (the A50's own gyro).
    gps : GpsSeries or None
        Positions of a GPS or of a Water Linked Underwater GPS: a ruler, never an input.
    gps_source : str
    counts : dict of str to int
        ``navlog_*``: records dropped and what dropped them (corrupt chunks, bytes skipped,
        checksum errors, records of other sources).
    notes : tuple of str
        What the reader found worth saying (the clock it took, a writer's known defect met).
    """

    path: Path
    kind: str
    streams: tuple[Stream, ...] = ()
    dvl: DvlSeries | None = None
    dvl_source: str = ""
    autopilot: WorldVelocity | None = None
    autopilot_source: str = ""
    attitude: AttitudeSeries | None = None
    heading_source: str = ""
    heading_absolute: bool = True
    gps: GpsSeries | None = None
    gps_source: str = ""
    counts: dict[str, int] = field(default_factory=dict)
    notes: tuple[str, ...] = ()


def unix_s_of_iso(text: str, utc_offset_h: float, where: Path, key: str) -> float:
    """An ISO 8601 date and time as Unix s (without an offset: UTC + ``utc_offset_h``); a
    :class:`DataError` naming ``where`` and ``key`` when it is not one."""
    try:
        when = datetime.fromisoformat(text)
    except ValueError:
        raise DataError(
            where,
            None,
            f"{key} = {text!r} is not an ISO 8601 date and time (2024-05-02T10:31:07.250+02:00)",
        ) from None
    if when.tzinfo is None:
        when = when.replace(tzinfo=timezone(timedelta(hours=utc_offset_h)))
    return (when - datetime(1970, 1, 1, tzinfo=UTC)).total_seconds()
