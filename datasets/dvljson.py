"""The Water Linked DVL A50's own JSON reports, as logged from its TCP stream (one JSON object a
line), in each protocol version.

What was read to write this (the code is this project's own): Water Linked's DVL protocol
pages (docs.waterlinked.com, "DVL A50/A125 TCP JSON API", json_v3.x; the version history: the
initial release sent velocities only, ``json_v2`` (2.0.8) added the dead-reckoning position and
the IMU, ``json_v3`` (2.1.0) added ``time_of_validity``, ``time_of_transmission`` and the
covariance); the drivers that parse them: waterlinked/dvl-a50-ros-driver (``publisher.py``,
e86b038), paagutie/dvl-a50 (``src/dvl-sensor.cpp``, 2eed27e), uri-ocean-robotics/waterlinked_dvl
(``waterlinked_dvl_tcp.cpp``: ``time_of_validity`` in microseconds, its warning that a DVL
whose clock is not synchronised must not be stamped by it); BlueOS's DVL extension
(``dvl.py``: ``time / 1000`` s is the report's dt).

=====================  ======================================================================
report                 read as
=====================  ======================================================================
velocity (``type``     ``vx``, ``vy`` in the DVL's frame (x forward, y right, z down: y
``"velocity"``; the    negated here to the project's y left), ``velocity_valid`` the bottom
old ``json_v1`` has    lock, ``fom`` (m/s) its own accuracy (said beside ``[noise]
no ``type``)           dvl_sigma_mps``, not an input); its time: ``time_of_validity`` (us,
                       the ping's centre) when there is one, else the sum of ``time`` (ms
                       since the report before) from an anchor (below)
dead reckoning         ``yaw`` (deg, the A50's own gyro, clockwise seen from above, relative to
(``"position_local"``) where it was reset: a heading with no North, said), ``ts`` (s)
others                 counted (configuration replies, IMU reports)
=====================  ======================================================================

Clocks: a ``time_of_validity`` of a wall clock (2000-2100) is Unix time; one before 2000 is an
A50 without NTP counting from its boot, put on ``[navlog] start``. Without ``time_of_validity``
(``json_v1``, ``json_v2``) the velocity reports' times are the running sum of their ``time``,
anchored on the dead-reckoning reports' ``ts`` when those are Unix times (the median of their
offsets to the sum at the report before them), else on ``[navlog] start``: a DataError says so
when there is neither.

Faults: a line that is not a JSON object (a corrupt or cut line), a report without its fields:
dropped and counted (``navlog_bad_lines``, one :class:`DataWarning` naming the first line). In
a log whose times are a running sum, a dropped line between two velocity reports took its
``time`` with it: the clock after it would run early by a report; the median ``time`` is added
in its place (counted ``navlog_clock_patches``, said).
"""

from __future__ import annotations

import array
import json
import math
import warnings
from pathlib import Path
from typing import Any

import numpy as np

from sonarslam.datasets.errors import DataError, DataWarning
from sonarslam.datasets.logfile import open_regular
from sonarslam.datasets.navrecords import (
    EARLIEST_UNIX_S,
    LATEST_UNIX_S,
    NavLog,
    NavLogSettings,
    stream_of,
    unix_s_of_iso,
)
from sonarslam.datasets.records import AttitudeSeries, DvlSeries

__all__ = ["DVL_JSON_KIND", "is_dvl_json", "read_dvl_json"]

DVL_JSON_KIND = "Water Linked DVL A50 JSON log"
#: Lines read to tell a DVL JSON log by content.
_SNIFF_LINES = 20


def _report(line: str) -> dict[str, Any] | None:
    try:
        obj = json.loads(line)
    except (ValueError, RecursionError):
        return None
    return obj if isinstance(obj, dict) else None


def _kind(obj: dict[str, Any]) -> str:
    """``velocity``, ``position_local`` or another report's type ("" none)."""
    kind = obj.get("type")
    if isinstance(kind, str):
        return kind
    return "velocity" if "vx" in obj and "vy" in obj else ""


def is_dvl_json(path: str | Path) -> bool:
    """A DVL A50 JSON log, by content: among its first lines a JSON object that is a velocity
    or dead-reckoning report."""
    p = Path(path)
    try:
        with open_regular(p) as fh:
            head = fh.read(1 << 14)
    except DataError:
        return False
    for line in head.split(b"\n")[:_SNIFF_LINES]:
        obj = _report(line.decode("utf-8", "replace").strip()) if line.strip() else None
        if obj is not None and _kind(obj) in ("velocity", "position_local"):
            return True
    return False


def _number(obj: dict[str, Any], key: str) -> float:
    v = obj[key]
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        raise TypeError(key)
    out = float(v)
    if not math.isfinite(out):
        raise ValueError(key)
    return out


def read_dvl_json(path: str | Path, settings: NavLogSettings | None = None) -> NavLog:
    """Read a DVL A50 JSON log (module docstring), a line at a time.

    Raises
    ------
    DataError
        Naming the file: not UTF-8, no velocity report, no clock to put the reports on.
    """
    p = Path(path)
    settings = settings or NavLogSettings()
    vel = {k: array.array("d") for k in ("tov", "dt_ms", "vx", "vy", "valid", "fom")}
    pos = {k: array.array("d") for k in ("ts", "yaw", "after_velocity")}
    formats: dict[str, int] = {}
    bad_lines: list[int] = []
    lost_after: list[int] = []  # the velocity reports read before each bad line
    others = 0
    with open_regular(p) as fh:
        for number, raw in enumerate(fh, start=1):
            try:
                line = raw.decode("utf-8").strip()
            except UnicodeDecodeError:
                line = "\0"
            if not line:
                continue
            obj = _report(line)
            kind = _kind(obj) if obj is not None else ""
            try:
                if obj is None:
                    raise ValueError("not JSON")
                if kind == "velocity":
                    row = (
                        _number(obj, "time_of_validity") if "time_of_validity" in obj else math.nan,
                        _number(obj, "time"),
                        _number(obj, "vx"),
                        _number(obj, "vy"),
                        1.0 if obj["velocity_valid"] is True else 0.0,
                        _number(obj, "fom") if "fom" in obj else math.nan,
                    )
                    for k, v in zip(vel, row, strict=True):
                        vel[k].append(v)
                    name = str(obj.get("format", "json_v1"))
                    formats[name] = formats.get(name, 0) + 1
                elif kind == "position_local":
                    pos["ts"].append(_number(obj, "ts"))
                    pos["yaw"].append(_number(obj, "yaw"))
                    pos["after_velocity"].append(float(len(vel["vx"]) - 1))
                else:
                    others += 1
            except (KeyError, TypeError, ValueError):
                bad_lines.append(number)
                lost_after.append(len(vel["vx"]))
    if bad_lines:
        warnings.warn(
            f"{p}: {len(bad_lines)} line(s) that are not a whole DVL report dropped (a corrupt"
            f" or cut line), the first line {bad_lines[0]}",
            DataWarning,
            stacklevel=2,
        )
    if not len(vel["vx"]):
        raise DataError(p, None, "no velocity report (a JSON line with vx, vy): not a DVL A50 log")
    a = {k: np.frombuffer(v, dtype=np.float64) for k, v in vel.items()}
    notes: list[str] = []
    t, patches = _velocity_times(p, a, pos, lost_after, settings, notes)
    counts = {
        "navlog_bad_lines": len(bad_lines),
        "navlog_clock_patches": patches,
        "navlog_other_reports": others,
    }
    valid = a["valid"] > 0.5
    order = np.argsort(t, kind="stable")
    dvl = DvlSeries(
        t[order],
        np.column_stack([a["vx"], -a["vy"]])[order],  # x forward, y right: to y left
        valid[order],
        np.full(t.size, np.nan),
        p,
    )
    fom = a["fom"][valid]
    fom = fom[np.isfinite(fom)]
    if fom.size:
        notes.append(
            f"fom (the DVL's own accuracy) median {float(np.median(fom)):.3g} m/s over"
            f" {fom.size} locked reports: not an input ([noise] dvl_sigma_mps is)"
        )
    notes.append("protocol: " + ", ".join(f"{k} ({v} reports)" for k, v in sorted(formats.items())))
    attitude = _dead_reckoning_heading(p, t, pos) if len(pos["ts"]) else None
    streams = [stream_of("velocity", dvl.t, "odometry (the DVL's own)")]
    if attitude is not None:
        streams.append(
            stream_of("position_local", attitude.t, "heading (the A50's gyro, relative)")
        )
    return NavLog(
        path=p,
        kind=DVL_JSON_KIND,
        streams=tuple(streams),
        dvl=dvl,
        dvl_source="the A50's velocity reports (vx, vy; y right negated)",
        attitude=attitude,
        heading_source=(
            "position_local yaw (the A50's own gyro, relative to where its dead reckoning was"
            " reset: no North)"
            if attitude is not None
            else ""
        ),
        heading_absolute=False,
        counts=counts,
        notes=tuple(notes),
    )


#: Dead-reckoning reports over which the running sum's offset is bracketed
#: (:func:`_anchor_offsets`): a lost velocity report steps the offset; within this many
#: reports the bracket follows it.
ANCHOR_WINDOW = 9


def _velocity_times(
    p: Path,
    a: dict[str, np.ndarray],
    pos: dict[str, array.array[float]],
    lost_after: list[int],
    settings: NavLogSettings,
    notes: list[str],
) -> tuple[np.ndarray, int]:
    """The velocity reports' Unix times by the module docstring's clocks, and the count of
    lost reports patched into a running sum."""
    tov = a["tov"]
    if np.isfinite(tov).all():
        t = tov * 1e-6
        if EARLIEST_UNIX_S <= float(t.min()) <= LATEST_UNIX_S:
            notes.append("clock: time_of_validity (us, the A50's wall clock)")
            return t, 0
        start = _start(p, settings, "its time_of_validity counts from the A50's boot (no NTP)")
        notes.append("clock: time_of_validity from the A50's boot, put on [navlog] start")
        return t - float(t.min()) + start, 0
    dt = a["dt_ms"].copy()
    n = dt.size
    ts = np.frombuffer(pos["ts"], dtype=np.float64)
    after = np.frombuffer(pos["after_velocity"], dtype=np.float64).astype(np.int64)
    anchored = (after >= 0) & (ts >= EARLIEST_UNIX_S) & (ts <= LATEST_UNIX_S)
    patches = 0
    if not len(ts):  # velocity reports only (json_v1): a bad line was a lost report
        median_dt = float(np.median(dt))
        for k in lost_after:
            if 0 < k < n:
                dt[k] += median_dt
                patches += 1
        if patches:
            notes.append(
                f"{patches} lost report(s) between velocity reports: each counted as one report"
                f" of the median time ({median_dt:.0f} ms), so that the clock after it does not"
                " run early"
            )
    cum = np.cumsum(dt) * 1e-3
    cum -= cum[0]
    if anchored.any():
        offsets = _anchor_offsets(ts[anchored], after[anchored], cum)
        notes.append(
            "clock: the running sum of the velocity reports' time (ms since the report before),"
            " anchored on the dead-reckoning reports' ts (Unix s) between them"
        )
        return cum + np.interp(np.arange(n), after[anchored], offsets), 0
    offset = _start(
        p,
        settings,
        "its velocity reports carry no clock but their time, ms since the report before (json_v1)",
    )
    notes.append(
        "clock: the running sum of the velocity reports' time (ms since the report before), from"
        " [navlog] start"
    )
    return cum + offset, patches


def _anchor_offsets(ts: np.ndarray, after: np.ndarray, cum: np.ndarray) -> np.ndarray:
    """The running sum's offset to Unix time at each dead-reckoning report: a report stamped
    ``ts`` came between the velocity reports ``after`` and ``after + 1``, so the offset lies in
    ``[ts - cum[after + 1], ts - cum[after]]``; over :data:`ANCHOR_WINDOW` reports the
    intersection of those intervals, its middle (the median of their middles where a lost
    report makes them disagree)."""
    last = cum.size - 1
    upper = ts - cum[after]
    lower = ts - cum[np.minimum(after + 1, last)]
    lower = np.where(after < last, lower, upper - 1.0)  # after the last: bounded above only
    half = ANCHOR_WINDOW // 2
    out = np.empty(ts.size)
    for j in range(ts.size):
        w = slice(max(0, j - half), j + half + 1)
        lo, hi = float(np.max(lower[w])), float(np.min(upper[w]))
        out[j] = 0.5 * (lo + hi) if lo <= hi else float(np.median(0.5 * (lower[w] + upper[w])))
    return out


def _start(p: Path, settings: NavLogSettings, why: str) -> float:
    if not settings.start:
        raise DataError(
            p,
            None,
            f"{why}: give the date and time of its first report as [navlog] start ="
            ' "2024-05-02T10:31:07.250+02:00" in the sonarslam.toml beside it',
        )
    return unix_s_of_iso(settings.start, settings.utc_offset_h, p, "[navlog] start")


def _dead_reckoning_heading(
    p: Path, t_vel: np.ndarray, pos: dict[str, array.array[float]]
) -> AttitudeSeries | None:
    """The A50's own heading (``position_local`` yaw: deg, clockwise, relative) as a yaw CCW
    (rad), at its ``ts`` when a wall clock's, else at the velocity report before it."""
    ts = np.frombuffer(pos["ts"], dtype=np.float64)
    yaw = -np.radians(np.frombuffer(pos["yaw"], dtype=np.float64))
    after = np.frombuffer(pos["after_velocity"], dtype=np.float64).astype(np.int64)
    if EARLIEST_UNIX_S <= float(ts.min()) <= LATEST_UNIX_S:
        t = ts.copy()
    else:
        t = np.where(after >= 0, t_vel[np.maximum(after, 0)], np.nan)
    keep = np.isfinite(t)
    if keep.sum() < 2:
        return None
    t, yaw = t[keep], yaw[keep]
    order = np.argsort(t, kind="stable")
    t, yaw = t[order], np.angle(np.exp(1j * yaw[order]))
    rate = np.gradient(np.unwrap(yaw), t) if np.all(np.diff(t) > 0) else np.zeros(t.size)
    return AttitudeSeries(t, yaw, rate, p)
