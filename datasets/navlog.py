"""A BlueROV2's navigation logs beside a sonar log (``--nav``): which file is which, by content,
and which of their streams becomes the odometry and the heading.

==============================  ============================================================
file (told by its content)      reader
==============================  ============================================================
QGroundControl ``.tlog``        :func:`sonarslam.datasets.mavlink.read_tlog`
ArduSub dataflash ``.bin``      :func:`sonarslam.datasets.mavlink.read_dataflash` (a Ping
                                Viewer log is a ``.bin`` too: told apart by its first bytes)
Water Linked A50 JSON           :func:`sonarslam.datasets.dvljson.read_dvl_json`
QGroundControl CSV export       :func:`sonarslam.datasets.qgccsv.read_qgc_csv`
==============================  ============================================================

From one or several of them (``--nav A --nav B``), :func:`navigation` takes

* the **odometry**: the DVL's own velocities where a log holds them (the A50's reports, the
  deltas it sent the autopilot); else the autopilot's velocity estimate, rotated into the
  heading's frame (so ``[mounting.dvl]`` becomes the AHRS's, said) with ``[noise]
  dvl_sigma_mps`` raised to at least :data:`AUTOPILOT_VELOCITY_SIGMA_MPS` (said): the
  estimate is smoothed by the autopilot's filter, its errors correlated over the filter's time
  constant, and a white noise of the DVL's sigma would count each of its samples as a new
  measurement. ``[navlog] odometry`` forces either;
* the **heading**: the autopilot's (referred to North) before the A50's own gyro (relative to
  its reset: the run's frame then turns with it, said);
* the **ruler**: a GPS or Underwater GPS, never an input. When the odometry is the autopilot's
  estimate and the log holds a GPS, the autopilot may have fused that GPS (ArduSub does, with
  ``GPS_TYPE`` MAVLink for a Water Linked Underwater GPS): a warning says the ruler is then not
  independent of what it measures.

``[navlog]`` of the ``sonarslam.toml`` beside the sonar log (and of ``--config``) sets the
clock of a log that has none and the odometry's choice
(:class:`sonarslam.datasets.navrecords.NavLogSettings`).
"""

from __future__ import annotations

import math
import tomllib
import warnings
from collections.abc import Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from sonarslam.datasets.config import DatasetConfig
from sonarslam.datasets.dvljson import DVL_JSON_KIND, is_dvl_json, read_dvl_json
from sonarslam.datasets.errors import DataError, DataWarning
from sonarslam.datasets.mavlink import (
    DATAFLASH_KIND,
    TLOG_KIND,
    is_dataflash,
    is_tlog,
    read_dataflash,
    read_tlog,
)
from sonarslam.datasets.navrecords import NavLog, NavLogSettings
from sonarslam.datasets.qgccsv import QGC_CSV_KIND, is_qgc_csv, read_qgc_csv
from sonarslam.datasets.records import AttitudeSeries, DvlSeries, GpsSeries
from sonarslam.settings import SettingError
from sonarslam.sonar.beam import Mounting

__all__ = [
    "AUTOPILOT_VELOCITY_SIGMA_MPS",
    "NAV_LOG_KINDS",
    "Navigation",
    "nav_log_kind",
    "is_nav_log",
    "read_nav_log",
    "navlog_settings",
    "navigation",
    "describe_nav_log",
]

#: The least 1-sigma (m/s) an autopilot's velocity estimate is taken with as odometry
#: (module docstring): at it, the dead reckoning's NEES on a simulated autopilot (the DVL held
#: between its samples, smoothed over 0.5 s, at 10 Hz) is the DVL's own deltas' (docs/data.md).
AUTOPILOT_VELOCITY_SIGMA_MPS = 0.2
#: What each kind of navigation log is, in words.
NAV_LOG_KINDS = {
    "tlog": TLOG_KIND,
    "dataflash": DATAFLASH_KIND,
    "dvl_json": DVL_JSON_KIND,
    "qgc_csv": QGC_CSV_KIND,
}
_READERS = {
    "tlog": read_tlog,
    "dataflash": read_dataflash,
    "dvl_json": read_dvl_json,
    "qgc_csv": read_qgc_csv,
}


def nav_log_kind(path: str | Path) -> str | None:
    """``"tlog"``, ``"dataflash"``, ``"dvl_json"`` or ``"qgc_csv"`` by the file's content (its
    name is not looked at), None for anything else."""
    p = Path(path)
    if not p.is_file():
        return None
    for kind, test in (
        ("dataflash", is_dataflash),
        ("tlog", is_tlog),
        ("qgc_csv", is_qgc_csv),
        ("dvl_json", is_dvl_json),
    ):
        if test(p):
            return kind
    return None


def is_nav_log(path: str | Path) -> bool:
    """A navigation log this module reads (:func:`nav_log_kind`)."""
    return nav_log_kind(path) is not None


def navlog_settings(*tomls: str | Path | None) -> NavLogSettings:
    """The ``[navlog]`` table of these ``sonarslam.toml`` files, the later's keys over the
    earlier's; a :class:`DataError` naming the file for an unknown key or a bad value."""
    out = NavLogSettings()
    for toml in tomls:
        if toml is None or not Path(toml).is_file():
            continue
        p = Path(toml)
        try:
            table = tomllib.loads(p.read_text(encoding="utf-8")).get("navlog", {})
        except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError):
            continue  # the configuration's reader names what is wrong with the file
        if not isinstance(table, dict):
            raise DataError(p, None, "[navlog] must be a table")
        known = {"start", "utc_offset_h", "odometry"}
        unknown = sorted(set(table) - known)
        if unknown:
            raise DataError(
                p, None, f"unknown key(s) {unknown} in [navlog]; allowed: {sorted(known)}"
            )
        values: dict[str, Any] = dict(table)
        for key in ("start", "odometry"):
            if key in values and not isinstance(values[key], str):
                raise DataError(p, None, f"[navlog] {key} must be a string, got {values[key]!r}")
        if "utc_offset_h" in values:
            v = values["utc_offset_h"]
            if isinstance(v, bool) or not isinstance(v, (int, float)):
                raise DataError(p, None, f"[navlog] utc_offset_h must be a number, got {v!r}")
            values["utc_offset_h"] = float(v)
        try:
            out = replace(out, **values)
        except (SettingError, ValueError) as exc:
            raise DataError(p, None, f"[navlog]: {exc}") from None
    return out


def read_nav_log(path: str | Path, settings: NavLogSettings | None = None) -> NavLog:
    """Read a navigation log of any kind :func:`nav_log_kind` tells; a :class:`DataError`
    naming the file for one it does not."""
    p = Path(path)
    kind = nav_log_kind(p)
    if kind is None:
        if not p.exists():
            raise DataError(p, None, "the navigation: no such file")
        raise DataError(
            p,
            None,
            "not a navigation log this reads (by its content): a QGroundControl .tlog or CSV"
            " export, an ArduSub dataflash .bin, a Water Linked DVL A50 JSON log (docs/data.md)",
        )
    return _READERS[kind](p, settings or NavLogSettings())


@dataclass(frozen=True)
class Navigation:
    """The odometry, heading and ruler taken from navigation logs (:func:`navigation`).

    Attributes
    ----------
    dvl : DvlSeries
        Velocities in the frame ``config.dvl_mounting`` says (m/s).
    attitude : AttitudeSeries
    gps : GpsSeries or None
        A ruler only.
    config : DatasetConfig
        The configuration given, with what the odometry's kind sets (module docstring).
    said : str
        Which stream is what, in one line (``Dataset.calibration`` carries it).
    counts : dict of str to int
        The logs' ``navlog_*`` counts, summed.
    """

    dvl: DvlSeries
    attitude: AttitudeSeries
    gps: GpsSeries | None
    config: DatasetConfig
    said: str
    counts: dict[str, int]


def _heading_frame_velocity(autopilot: Any, attitude: AttitudeSeries, source: str) -> DvlSeries:
    """An autopilot's East-North velocity turned into the heading's frame at each of its times
    (the heading unwrapped and interpolated; outside the heading's span: no lock)."""
    t = autopilot.t
    yaw = np.interp(t, attitude.t, np.unwrap(attitude.yaw_rad))
    inside = (t >= attitude.t[0]) & (t <= attitude.t[-1]) & np.isfinite(autopilot.v_en_mps).all(1)
    c, s = np.cos(yaw), np.sin(yaw)
    e, n = autopilot.v_en_mps[:, 0], autopilot.v_en_mps[:, 1]
    v = np.column_stack([c * e + s * n, -s * e + c * n])
    v[~inside] = 0.0
    return DvlSeries(
        t.copy(), v, inside, np.full(t.size, np.nan), autopilot.path, autopilot.resolution_mps
    )


def navigation(
    logs: Sequence[NavLog], config: DatasetConfig, settings: NavLogSettings | None = None
) -> Navigation:
    """The odometry, the heading and the ruler of these logs (module docstring).

    Raises
    ------
    DataError
        Naming the logs: no heading, no odometry (or not the one ``[navlog] odometry`` asks).
    """
    settings = settings or NavLogSettings()
    names = ", ".join(str(log.path) for log in logs)
    where = logs[0].path if logs else Path("--nav")
    headings = [log for log in logs if log.attitude is not None]
    heading = next((log for log in headings if log.heading_absolute), None) or next(
        iter(headings), None
    )
    if heading is None or heading.attitude is None:
        kinds = "; ".join(f"{log.path.name}: {log.kind}" for log in logs)
        raise DataError(
            where,
            None,
            f"no heading in {kinds}: the A50's json_v1 holds velocities only; give the"
            " autopilot's log too (--nav dive.tlog, an ArduSub dataflash .bin or a"
            " QGroundControl CSV)",
        )
    own = next((log for log in logs if log.dvl is not None), None)
    pilot = next((log for log in logs if log.autopilot is not None), None)
    choice = settings.odometry
    if choice == "dvl" and own is None:
        raise DataError(where, None, f"[navlog] odometry = 'dvl': no DVL velocities in {names}")
    if choice == "autopilot" and pilot is None:
        raise DataError(
            where, None, f"[navlog] odometry = 'autopilot': no autopilot velocity in {names}"
        )
    if own is None and pilot is None:
        raise DataError(
            where,
            None,
            f"no odometry in {names}: neither the DVL's own velocities (VISION_POSITION_DELTA,"
            " VISO, the A50's reports) nor the autopilot's velocity (LOCAL_POSITION_NED,"
            " GLOBAL_POSITION_INT, XKF1)",
        )
    attitude = heading.attitude
    gps_log = next((log for log in logs if log.gps is not None), None)
    parts = []
    if own is not None and choice != "autopilot":
        assert own.dvl is not None
        dvl = own.dvl
        parts.append(f"odometry {own.dvl_source} of {own.path.name}")
    else:
        assert pilot is not None and pilot.autopilot is not None
        dvl = _heading_frame_velocity(pilot.autopilot, attitude, pilot.autopilot_source)
        config = _autopilot_config(config, pilot)
        parts.append(
            f"odometry {pilot.autopilot_source} of {pilot.path.name}, turned into the heading's"
            f" frame ([mounting.dvl] = [mounting.ahrs]; [noise] dvl_sigma_mps"
            f" {config.noise.dvl_sigma_mps:g})"
        )
        if gps_log is not None:
            warnings.warn(
                f"{pilot.path}: the odometry is the autopilot's velocity estimate and"
                f" {gps_log.path.name} holds a GPS ({gps_log.gps_source}): an autopilot that"
                " fuses that GPS (ArduSub with GPS_TYPE MAVLink takes a Water Linked Underwater"
                " GPS so) gives a velocity that is not independent of the ruler, and the run's"
                " error against it reads too good; log the DVL's own deltas"
                " (VISION_POSITION_DELTA) or its JSON, or leave the GPS out of the autopilot",
                DataWarning,
                stacklevel=2,
            )
    parts.append(f"heading {heading.heading_source} of {heading.path.name}")
    if not heading.heading_absolute:
        warnings.warn(
            f"{heading.path}: the heading is the A50's own gyro, relative to where its dead"
            " reckoning was reset: the run's frame is turned from East-North by that unknown"
            " angle (a GPS ruler compares after a rigid fit only); give the autopilot's log"
            " for a heading referred to North",
            DataWarning,
            stacklevel=2,
        )
    if gps_log is not None:
        parts.append(f"ruler {gps_log.gps_source} of {gps_log.path.name}")
    counts: dict[str, int] = {}
    for log in logs:
        for k, v in log.counts.items():
            counts[k] = counts.get(k, 0) + v
    return Navigation(
        dvl=dvl,
        attitude=attitude,
        gps=gps_log.gps if gps_log is not None else None,
        config=config,
        said="navigation: " + "; ".join(parts),
        counts=counts,
    )


def _autopilot_config(config: DatasetConfig, log: NavLog) -> DatasetConfig:
    """``config`` for the autopilot's velocity as odometry: the DVL frame is the heading's
    (the AHRS's mounting, no lever arm: the estimate is the vehicle's), its sigma at least
    :data:`AUTOPILOT_VELOCITY_SIGMA_MPS` (both said in a warning when they change it)."""
    ahrs = config.ahrs_mounting
    mounting = Mounting(
        0.0,
        0.0,
        ahrs.yaw_rad,
        source=f"the autopilot's velocity of {log.path.name}, in the"
        " heading's frame (sonarslam.datasets.navlog)",
    )
    noise = config.noise
    changed = []
    d = config.dvl_mounting
    if (d.x_m, d.y_m, d.yaw_rad) != (0.0, 0.0, ahrs.yaw_rad):
        changed.append(
            f"[mounting.dvl] ({d.x_m:g} m, {d.y_m:g} m, {math.degrees(d.yaw_rad):g} deg) replaced"
            f" by the AHRS's (0 m, 0 m, {math.degrees(ahrs.yaw_rad):g} deg): the velocity is the"
            " vehicle's, in the heading's frame"
        )
    if noise.dvl_sigma_mps < AUTOPILOT_VELOCITY_SIGMA_MPS:
        changed.append(
            f"[noise] dvl_sigma_mps {noise.dvl_sigma_mps:g} raised to"
            f" {AUTOPILOT_VELOCITY_SIGMA_MPS:g} m/s (its errors are its filter's, correlated"
            " over its time constant)"
        )
        noise = replace(noise, dvl_sigma_mps=AUTOPILOT_VELOCITY_SIGMA_MPS)
    if changed:
        warnings.warn(
            f"{log.path}: the odometry is the autopilot's velocity estimate: " + "; ".join(changed),
            DataWarning,
            stacklevel=3,
        )
    return replace(config, dvl_mounting=mounting, noise=noise)


def describe_nav_log(log: NavLog) -> list[str]:
    """``sonarslam info``'s lines for a navigation log alone: its kind, every stream (count,
    rate, span, gaps, what it is taken for), the odometry and the heading it would give,
    faults and notes."""
    lines = [f"{log.path}: {log.kind}"]
    width = max((len(s.name) for s in log.streams), default=4)
    t0 = min((s.t_first_s for s in log.streams if s.count), default=math.nan)
    for s in log.streams:
        if not s.count:
            lines.append(f"  {s.name:<{width}}  none{'  ' + s.use if s.use else ''}")
            continue
        span = s.t_last_s - s.t_first_s
        gaps = (
            f"{s.gaps} gap(s), longest {s.longest_gap_s:.1f} s"
            if s.gaps
            else "no gap"
            if s.use and not s.use.startswith("not read")
            else "gaps not looked for"
        )
        lines.append(
            f"  {s.name:<{width}} {s.count:>8}  {s.rate_hz:7.2f} Hz  {s.t_first_s - t0:8.1f} to"
            f" {s.t_first_s - t0 + span:8.1f} s  {gaps}{'  -> ' + s.use if s.use else ''}"
        )
    if log.streams and math.isfinite(t0):
        lines.append(f"  (times from the log's first record, Unix {t0:.3f} s)")
    odometry = (
        log.dvl_source
        if log.dvl is not None
        else f"{log.autopilot_source}, turned into the heading's frame"
        if log.autopilot is not None
        else "none (give a log that has it: --nav twice)"
    )
    lines.append(f"  odometry: {odometry}")
    lines.append(
        "  heading: "
        + (
            log.heading_source
            if log.attitude is not None
            else "none (give the autopilot's log too: --nav twice)"
        )
    )
    lines.append(f"  ruler: {log.gps_source or 'none'}")
    faults = {k.removeprefix("navlog_"): v for k, v in log.counts.items() if v}
    lines.append(f"  dropped: {faults or 'nothing'}")
    lines.extend(f"  {note}" for note in log.notes)
    return lines
