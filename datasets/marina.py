"""Readers of the navigation logs in the marina layout (Ribas et al. 2008).

Each reader returns a series of arrays (one row per log row, time never decreasing) with frames
and units fixed here, once: yaw counter-clockwise from East in rad (the logs' headings grow
clockwise from North: ``yaw = pi/2 - heading``), velocities in m/s, positions in local
East-North metres with the origin at the first DGPS fix. Bad input follows the policy of
:mod:`sonarslam.datasets.logfile`.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from sonarslam.datasets.errors import DataError
from sonarslam.datasets.geodesy import ddmm_to_degrees, geodetic_to_local_en
from sonarslam.datasets.logfile import Table, read_table
from sonarslam.datasets.records import AttitudeSeries, DvlSeries, GpsSeries
from sonarslam.features.geometry import FloatArray, wrap_angle
from sonarslam.sonar.beam import SonarHead

__all__ = [
    "DvlSeries",
    "AttitudeSeries",
    "GpsSeries",
    "read_dvl",
    "read_mti",
    "read_dgps",
    "read_is_timestamps",
    "read_setup",
    "heading_deg_to_yaw_rad",
]

DVL_COLUMNS = 32
MTI_COLUMNS = 10
DGPS_COLUMNS = 10


def heading_deg_to_yaw_rad(heading_deg: np.ndarray) -> FloatArray:
    """Heading clockwise from North (deg) to yaw counter-clockwise from East (rad)."""
    return wrap_angle(np.pi / 2.0 - np.deg2rad(heading_deg))


def _first_bad(table: Table, bad: np.ndarray, message: str) -> None:
    """Raise :class:`DataError` at the first row flagged in ``bad`` (N,) bool."""
    rows = np.flatnonzero(bad)
    if rows.size:
        raise DataError(table.path, int(table.line_numbers[rows[0]]), message)


def read_dvl(path: str | Path) -> DvlSeries:
    """Read ``*_DVL.log`` (32 columns; see the marina README).

    Velocities ``bottomVelX/Y`` (cm/s, DVL frame) become m/s; ``bottomVelStatus == 1`` is the
    bottom-lock flag, kept as ``valid`` (invalid rows are kept, flagged, never silently used).
    The DVL's own date fields are wrong in the marina log and are ignored (``logTime`` is used).
    A status other than 0/1 or a compass heading beyond +-360 deg is a :class:`DataError`;
    an implausible speed is the gates' (:mod:`sonarslam.datasets.gates`).
    """
    table = read_table(path, n_columns=DVL_COLUMNS, used_columns=(0, 11, 12, 14, 22))
    d = table.data
    status = d[:, 14]
    _first_bad(table, (status != 0.0) & (status != 1.0), "bottomVelStatus not 0 or 1")
    _first_bad(table, np.abs(d[:, 22]) > 360.0, "DVL heading outside +-360 deg")
    return DvlSeries(
        t=d[:, 0].copy(),
        v_mps=d[:, 11:13] / 100.0,
        valid=status == 1.0,
        heading_rad=heading_deg_to_yaw_rad(d[:, 22]),
        path=table.path,
    )


def read_mti(path: str | Path) -> AttitudeSeries:
    """Read ``*_MTi.log``. Its header is wrong; the real columns are (marina README)
    ``logTime, roll, pitch, yaw`` (deg, yaw a heading clockwise from North),
    ``rate_x, rate_y, rate_z`` (rad/s, rate_z positive clockwise seen from above),
    ``acc_x, acc_y, acc_z`` (m/s^2)."""
    table = read_table(path, n_columns=MTI_COLUMNS, used_columns=(0, 3, 6))
    d = table.data
    _first_bad(table, np.abs(d[:, 3]) > 360.0, "yaw outside +-360 deg")
    return AttitudeSeries(
        t=d[:, 0].copy(),
        yaw_rad=heading_deg_to_yaw_rad(d[:, 3]),
        yaw_rate_rad_per_s=-d[:, 6],
        path=table.path,
    )


#: GPS fix qualities (NMEA GGA): 1 GPS, 2 DGPS, 3 PPS, 4 RTK, 5 float RTK; 0 and 6-8 are none.
GPS_FIX_STATUS = (1.0, 2.0, 3.0, 4.0, 5.0)


def _ddmm(table: Table, column: int, limit_deg: float, name: str) -> FloatArray:
    """Degrees of a ``ddmm.mmmm`` column; minutes >= 60 or beyond ``limit_deg`` is a DataError."""
    v = np.abs(table.data[:, column])
    minutes = v - 100.0 * np.floor(v / 100.0)
    _first_bad(table, minutes >= 60.0, f"{name} is not ddmm.mmmm (minutes >= 60)")
    deg = ddmm_to_degrees(table.data[:, column])
    _first_bad(table, np.abs(deg) > limit_deg, f"{name} beyond +-{limit_deg:g} deg")
    return deg


def read_dgps(path: str | Path) -> GpsSeries:
    """Read ``*_DGPS.log``: latitude/longitude as ``ddmm.mmmm`` to local East-North metres
    (pymap3d, WGS-84) with the origin at the first fix.

    ``status`` 1-5 is a fix; 0 and 6-8 (none, estimated, manual, simulated), and the 0/0
    placeholder of a receiver without a fix, are kept as rows without ``fix`` (the gates drop
    them, :mod:`sonarslam.datasets.gates`); another status, minutes >= 60 or an impossible latitude or
    longitude is a :class:`DataError`.
    """
    table = read_table(path, n_columns=DGPS_COLUMNS, used_columns=(0, 1, 2, 3))
    d = table.data
    status = d[:, 3]
    _first_bad(
        table, (status != np.rint(status)) | (status < 0) | (status > 8), "status is not 0-8"
    )
    lat = _ddmm(table, 1, 90.0, "latitude")
    lon = _ddmm(table, 2, 180.0, "longitude")
    fix = np.isin(status, GPS_FIX_STATUS) & ~((lat == 0.0) & (lon == 0.0))
    if not fix.any():
        raise DataError(table.path, None, "no row with a position fix")
    first = int(np.flatnonzero(fix)[0])
    lat0, lon0 = float(lat[first]), float(lon[first])
    return GpsSeries(
        t=d[:, 0].copy(),
        en_m=geodetic_to_local_en(lat, lon, lat0, lon0),
        origin_lat_lon_deg=(lat0, lon0),
        fix=fix,
        path=table.path,
    )


def read_is_timestamps(path: str | Path) -> FloatArray:
    """Read ``*_IS_timestamps.log``: one row per sonar beam, ``logTime sensorTime``; returns
    the log times (Unix s), shape (N,)."""
    return read_table(path, n_columns=2, used_columns=(0,)).data[:, 0].copy()


#: A step divides the turn when ``2 pi / step`` is this close to a whole number of beams.
_TURN_TOLERANCE = 0.01


def read_setup(path: str | Path) -> tuple[float, float, float]:
    """Read ``*_SETUP.log``: ``range_m bin_size_m step_rad`` of the sonar head (one row).

    The range must be a whole number of bins, and the step a whole division of the turn (to
    0.01 of a beam; the step returned is exactly ``2 pi / n``): so a value cut short in the
    file's last line (``0.03`` for ``0.0314159...``) is found, not used. The head's limits are
    :class:`sonarslam.sonar.beam.SonarHead`'s.
    """
    table = read_table(path, n_columns=3, time_column=None, trust_last_line=True)
    line = int(table.line_numbers[0])
    if table.data.shape[0] > 1:
        raise DataError(table.path, int(table.line_numbers[1]), "a second setup row")
    range_m, bin_m, step_rad = (float(v) for v in table.data[0])
    if not (range_m > 0 and bin_m > 0 and step_rad > 0):
        raise DataError(table.path, line, "range, bin size and step must be positive")
    n_bins = range_m / bin_m
    if not (n_bins < 2**31 and abs(n_bins - round(n_bins)) <= 1e-6 * n_bins):
        raise DataError(
            table.path, line, f"range {range_m:g} m is not a whole number of {bin_m:g} m bins"
        )
    beams = 2.0 * math.pi / step_rad
    if not (2 <= round(beams) < 2**31 and abs(beams - round(beams)) <= _TURN_TOLERANCE):
        raise DataError(
            table.path, line, f"step {step_rad:.6g} rad is not a whole division of the turn"
        )
    step_rad = 2.0 * math.pi / round(beams)
    try:
        SonarHead(n_bins=int(round(n_bins)), bin_size_m=bin_m, step_rad=step_rad)
    except ValueError as exc:
        raise DataError(table.path, line, str(exc)) from None
    return range_m, bin_m, step_rad
