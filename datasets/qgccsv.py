"""QGroundControl's CSV telemetry export ("Save CSV log of telemetry data"): a row a second of
the vehicle's facts as QGroundControl shows them.

What was read to write this (the code is this project's own): QGroundControl's
``src/Vehicle/Vehicle.cc`` (``_initializeCsv``, ``_writeCsvLine``: the header ``Timestamp`` then
every fact of the vehicle and of its fact groups as ``group.fact``; a row every 1000 ms from a
timer; the time ``yyyy-MM-dd hh:mm:ss.zzz`` of the computer's local clock; each value its
``cookedValueString``, so in display units with the fact's display decimals; the file named
``yyyy-MM-dd hh-mm-ss vehicle<id>.csv``) and its fact metadata
(``src/Vehicle/FactGroups/VehicleFact.json``: ``heading`` deg with 0 decimals, ``yawRate``
deg/s with 1; ``LocalPositionFact.json``: ``vx``, ``vy`` m/s with 1 decimal, from
``LOCAL_POSITION_NED``; ``GPSFact.json``: ``lat``, ``lon`` with 7 decimals, ``lock`` an enum
shown by its name, "3D Lock").

==========================  =================================================================
column                      read as
==========================  =================================================================
``Timestamp``               local time: Unix = it less ``[navlog] utc_offset_h``
``heading``, ``yawRate``    the heading (compass deg to CCW from East rad) and its rate
                            (``-yawRate``, rad/s); without ``yawRate``, the heading's change
``localPosition.vx``,       the autopilot's velocity estimate (North, East; m/s)
``localPosition.vy``
``gps.lat``, ``gps.lon``,   a ruler (rows with ``gps.lock`` of a 2D lock or better)
``gps.lock``
==========================  =================================================================

A coarse navigation, said by ``sonarslam info``: one row a second, the heading in whole
degrees (a 0.29 deg standard deviation of rounding), the velocity to 0.1 m/s (0.029 m/s); and
the velocity is the autopilot's estimate, not a measurement. QGroundControl converts speeds to
the units its settings display: the reader cannot see them (m/s is the default). An empty cell,
``nan`` or QGroundControl's ``--.--`` is no value.

Faults: a row of another number of cells, a time that is not ``yyyy-MM-dd hh:mm:ss.zzz``, a
value that is not a number where one belongs: dropped and counted (``navlog_bad_lines``, one
:class:`DataWarning` naming the first line).
"""

from __future__ import annotations

import array
import csv
import io
import math
import re
import warnings
from datetime import UTC, datetime, timedelta, timezone
from pathlib import Path

import numpy as np

from sonarslam.datasets.errors import DataError, DataWarning
from sonarslam.datasets.geodesy import geodetic_to_local_en
from sonarslam.datasets.logfile import open_regular
from sonarslam.datasets.navrecords import (
    NavLog,
    NavLogSettings,
    WorldVelocity,
    stream_of,
)
from sonarslam.datasets.records import AttitudeSeries, GpsSeries

__all__ = ["QGC_CSV_KIND", "QGC_GPS_LOCKS", "is_qgc_csv", "read_qgc_csv"]

QGC_CSV_KIND = "QGroundControl CSV telemetry export"
#: ``gps.lock``'s names (``GPSFact.json`` enumStrings) and their values.
QGC_GPS_LOCKS = {
    "None": 0,
    "No Fix": 1,
    "2D Lock": 2,
    "3D Lock": 3,
    "3D DGPS Lock": 4,
    "3D RTK GPS Lock (float)": 5,
    "3D RTK GPS Lock (fixed)": 6,
    "Static (fixed)": 7,
}
_STAMP = re.compile(r"(\d{4})-(\d\d)-(\d\d) (\d\d):(\d\d):(\d\d)\.(\d{3})")
_EMPTY = ("", "nan", "-nan", "--.--", "n/a")
#: ``localPosition.vx``, ``vy``'s display decimals (``LocalPositionFact.json``): 1, so 0.1 m/s.
QGC_VELOCITY_RESOLUTION_MPS = 0.1
_COLUMNS = ("heading", "yawRate", "localPosition.vx", "localPosition.vy", "gps.lat", "gps.lon")


def is_qgc_csv(path: str | Path) -> bool:
    """A QGroundControl CSV export, by content: its header starts ``Timestamp,``."""
    try:
        with open_regular(Path(path)) as fh:
            return fh.read(10) == b"Timestamp,"
    except DataError:
        return False


def _cell(text: str) -> float:
    t = text.strip()
    if t.lower() in _EMPTY:
        return math.nan
    if t in QGC_GPS_LOCKS:
        return float(QGC_GPS_LOCKS[t])
    v = float(t)  # ValueError: not a number
    return v if math.isfinite(v) else math.nan


def read_qgc_csv(path: str | Path, settings: NavLogSettings | None = None) -> NavLog:
    """Read a QGroundControl CSV export (module docstring).

    Raises
    ------
    DataError
        Naming the file: not UTF-8 text, no ``Timestamp`` or ``heading`` column, no row.
    """
    p = Path(path)
    settings = settings or NavLogSettings()
    zone = timezone(timedelta(hours=settings.utc_offset_h))
    cols = {k: array.array("d") for k in ("t", *_COLUMNS, "gps.lock")}
    bad: list[int] = []
    with open_regular(p) as fh:
        text = io.TextIOWrapper(fh, encoding="utf-8", newline="")
        try:
            rows = csv.reader(text)
            header = [h.strip() for h in next(rows, [])]
            if not header or header[0] != "Timestamp" or "heading" not in header:
                raise DataError(
                    p, 1, "not a QGroundControl CSV export: its header needs Timestamp, heading"
                )
            at = {h: i for i, h in enumerate(header)}
            for cells in rows:
                number = rows.line_num
                if not cells:
                    continue
                try:
                    if len(cells) != len(header):
                        raise ValueError("cells")
                    found = _STAMP.fullmatch(cells[0].strip())
                    if found is None:
                        raise ValueError("stamp")
                    y, mo, d, h, mi, s, ms = (int(g) for g in found.groups())
                    when = datetime(y, mo, d, h, mi, s, ms * 1000, tzinfo=zone)
                    values = [
                        _cell(cells[at[c]]) if c in at else math.nan
                        for c in (*_COLUMNS, "gps.lock")
                    ]
                except ValueError:
                    bad.append(number)
                    continue
                cols["t"].append((when - datetime(1970, 1, 1, tzinfo=UTC)).total_seconds())
                for c, v in zip((*_COLUMNS, "gps.lock"), values, strict=True):
                    cols[c].append(v)
        except UnicodeDecodeError:
            raise DataError(p, None, "not UTF-8 text") from None
        except csv.Error as exc:
            raise DataError(p, rows.line_num, f"not a CSV row: {exc}") from None
        finally:
            text.detach()
    if bad:
        warnings.warn(
            f"{p}: {len(bad)} row(s) dropped (another number of cells, a time that is not"
            f" yyyy-MM-dd hh:mm:ss.zzz, or a value that is not a number), the first line {bad[0]}",
            DataWarning,
            stacklevel=2,
        )
    a = {k: np.frombuffer(v, dtype=np.float64) for k, v in cols.items()}
    t = a["t"]
    if not t.size:
        raise DataError(p, None, "no row")
    order = np.argsort(t, kind="stable")
    a = {k: v[order] for k, v in a.items()}
    t = a["t"]
    has = np.isfinite(a["heading"])
    attitude = None
    if has.sum() >= 2:
        yaw = np.angle(np.exp(1j * np.radians(90.0 - a["heading"][has])))
        rate = -np.radians(a["yawRate"][has])
        if not np.isfinite(rate).all():
            rate = np.gradient(np.unwrap(yaw), t[has])
        attitude = AttitudeSeries(t[has], yaw, rate, p)
    vel = np.isfinite(a["localPosition.vx"]) & np.isfinite(a["localPosition.vy"])
    autopilot = None
    if vel.any():
        v_en = np.column_stack([a["localPosition.vy"][vel], a["localPosition.vx"][vel]])
        autopilot = WorldVelocity(t[vel], v_en, p, QGC_VELOCITY_RESOLUTION_MPS)
    fix = np.isfinite(a["gps.lat"]) & np.isfinite(a["gps.lon"])
    fix &= ~((a["gps.lat"] == 0.0) & (a["gps.lon"] == 0.0))
    lock = a["gps.lock"]
    fix &= ~(np.isfinite(lock) & (lock < 2))
    gps = None
    if fix.any():
        lat, lon = a["gps.lat"][fix], a["gps.lon"][fix]
        origin = (float(lat[0]), float(lon[0]))
        gps = GpsSeries(t[fix], geodetic_to_local_en(lat, lon, *origin), origin, None, p)
    return NavLog(
        path=p,
        kind=QGC_CSV_KIND,
        streams=(
            stream_of("heading", t[has], "heading (whole degrees)"),
            stream_of("localPosition.vx/vy", t[vel], "the autopilot's velocity (0.1 m/s)"),
            stream_of("gps.lat/lon", t[fix], "ruler"),
        ),
        autopilot=autopilot,
        autopilot_source="localPosition.vx, vy (the autopilot's estimate, 0.1 m/s, 1 Hz)",
        attitude=attitude,
        heading_source="heading (the autopilot's, whole degrees, 1 Hz)",
        heading_absolute=True,
        gps=gps,
        gps_source="gps.lat, gps.lon (the autopilot's GPS)" if gps is not None else "",
        counts={"navlog_bad_lines": len(bad)},
        notes=(
            f"clock: the logging computer's local time, UTC{settings.utc_offset_h:+g} h"
            " ([navlog] utc_offset_h)",
            "coarse: one row a second, heading in whole degrees, velocity to 0.1 m/s"
            " (QGroundControl's display decimals)",
        ),
    )
