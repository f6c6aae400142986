"""Readers of the navigation logs in the marina layout (Ribas et al. 2008).

Each reader returns a series of arrays (one row per log row, time never decreasing) with frames
and units fixed here, once: yaw counter-clockwise from East in rad (the logs' headings grow
clockwise from North: ``yaw = pi/2 - heading``), velocities in m/s, positions in local
East-North metres with the origin at the first DGPS fix. Bad input follows the policy of
:mod:`datasets.logfile`.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from datasets.errors import DataError
from datasets.geodesy import ddmm_to_degrees, geodetic_to_local_en
from datasets.logfile import read_table
from datasets.records import AttitudeSeries, DvlSeries, GpsSeries
from features.geometry import FloatArray, wrap_angle

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


def read_dvl(path: str | Path) -> DvlSeries:
    """Read ``*_DVL.log`` (32 columns; see the marina README).

    Velocities ``bottomVelX/Y`` (cm/s, DVL frame) become m/s; ``bottomVelStatus == 1`` is the
    bottom-lock flag, kept as ``valid`` (invalid rows are kept, flagged, never silently used).
    The DVL's own date fields are wrong in the marina log and are ignored (``logTime`` is used).
    """
    table = read_table(path, n_columns=DVL_COLUMNS)
    d = table.data
    status = d[:, 14]
    odd = np.flatnonzero((status != 0.0) & (status != 1.0))
    if odd.size:
        raise DataError(table.path, int(table.line_numbers[odd[0]]), "bottomVelStatus not 0 or 1")
    return DvlSeries(
        t=d[:, 0].copy(),
        v_mps=d[:, 11:13] / 100.0,
        valid=status == 1.0,
        heading_rad=heading_deg_to_yaw_rad(d[:, 22]),
    )


def read_mti(path: str | Path) -> AttitudeSeries:
    """Read ``*_MTi.log``. Its header is wrong; the real columns are (marina README)
    ``logTime, roll, pitch, yaw`` (deg, yaw a heading clockwise from North),
    ``rate_x, rate_y, rate_z`` (rad/s, rate_z positive clockwise seen from above),
    ``acc_x, acc_y, acc_z`` (m/s^2)."""
    table = read_table(path, n_columns=MTI_COLUMNS)
    d = table.data
    bad = np.flatnonzero(np.abs(d[:, 3]) > 360.0)
    if bad.size:
        raise DataError(table.path, int(table.line_numbers[bad[0]]), "yaw outside +-360 deg")
    return AttitudeSeries(
        t=d[:, 0].copy(), yaw_rad=heading_deg_to_yaw_rad(d[:, 3]), yaw_rate_radps=-d[:, 6]
    )


def read_dgps(path: str | Path) -> GpsSeries:
    """Read ``*_DGPS.log``: latitude/longitude as ``ddmm.mmmm`` to local East-North metres
    (pymap3d, WGS-84) with the origin at the first fix."""
    table = read_table(path, n_columns=DGPS_COLUMNS)
    d = table.data
    lat = ddmm_to_degrees(d[:, 1])
    lon = ddmm_to_degrees(d[:, 2])
    bad = np.flatnonzero((np.abs(lat) > 90.0) | (np.abs(lon) > 180.0))
    if bad.size:
        raise DataError(
            table.path, int(table.line_numbers[bad[0]]), "latitude/longitude out of range"
        )
    lat0, lon0 = float(lat[0]), float(lon[0])
    return GpsSeries(
        t=d[:, 0].copy(),
        en_m=geodetic_to_local_en(lat, lon, lat0, lon0),
        origin_lat_lon_deg=(lat0, lon0),
    )


def read_is_timestamps(path: str | Path) -> FloatArray:
    """Read ``*_IS_timestamps.log``: one row per sonar beam, ``logTime sensorTime``; returns
    the log times (Unix s), shape (N,)."""
    return read_table(path, n_columns=2).data[:, 0].copy()


def read_setup(path: str | Path) -> tuple[float, float, float]:
    """Read ``*_SETUP.log``: ``range_m bin_size_m step_rad`` of the sonar head."""
    table = read_table(path, n_columns=3, time_column=None)
    range_m, bin_m, step_rad = (float(v) for v in table.data[0])
    if not (range_m > 0 and bin_m > 0 and 0 < step_rad < np.pi):
        raise DataError(
            table.path, int(table.line_numbers[0]), "range, bin size and step must be positive"
        )
    return range_m, bin_m, step_rad
