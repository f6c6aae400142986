"""Geodesy at the edge: NMEA-style ``ddmm.mmmm`` angles and local East-North metres (pymap3d)."""

from __future__ import annotations

import numpy as np
import numpy.typing as npt
import pymap3d

from sonarslam.features.geometry import FloatArray

__all__ = ["ddmm_to_degrees", "degrees_to_ddmm", "geodetic_to_local_en", "local_en_to_geodetic"]


def ddmm_to_degrees(ddmm: npt.ArrayLike) -> FloatArray:
    """``4212.225`` (42 deg 12.225 min) to decimal degrees; the sign is kept."""
    v = np.asarray(ddmm, dtype=np.float64)
    a = np.abs(v)
    deg = np.floor(a / 100.0)
    return np.asarray(np.sign(v) * (deg + (a - 100.0 * deg) / 60.0))


def degrees_to_ddmm(degrees: npt.ArrayLike) -> FloatArray:
    """Decimal degrees to ``ddmm.mmmm``; inverse of :func:`ddmm_to_degrees`."""
    v = np.asarray(degrees, dtype=np.float64)
    a = np.abs(v)
    deg = np.floor(a)
    return np.asarray(np.sign(v) * (deg * 100.0 + (a - deg) * 60.0))


def geodetic_to_local_en(
    lat_deg: npt.ArrayLike, lon_deg: npt.ArrayLike, lat0_deg: float, lon0_deg: float
) -> FloatArray:
    """WGS-84 latitude/longitude to local East-North metres about an origin (height 0).

    Returns
    -------
    ndarray, shape (N, 2)
        ``(east_m, north_m)``.
    """
    lat = np.asarray(lat_deg, dtype=np.float64)
    lon = np.asarray(lon_deg, dtype=np.float64)
    e, n, _ = pymap3d.geodetic2enu(lat, lon, np.zeros_like(lat), lat0_deg, lon0_deg, 0.0)
    return np.stack([np.asarray(e, dtype=np.float64), np.asarray(n, dtype=np.float64)], axis=-1)


def local_en_to_geodetic(
    east_m: npt.ArrayLike, north_m: npt.ArrayLike, lat0_deg: float, lon0_deg: float
) -> tuple[FloatArray, FloatArray]:
    """Inverse of :func:`geodetic_to_local_en`: ``(lat_deg, lon_deg)``."""
    e = np.asarray(east_m, dtype=np.float64)
    n = np.asarray(north_m, dtype=np.float64)
    lat, lon, _ = pymap3d.enu2geodetic(e, n, np.zeros_like(e), lat0_deg, lon0_deg, 0.0)
    return np.asarray(lat, dtype=np.float64), np.asarray(lon, dtype=np.float64)
