"""Typed records of the merged, time-ordered sensor stream.

Frames and units are fixed in the readers: yaw angles are counter-clockwise from East (rad),
velocities are in the sensor's own frame (m/s), positions are local East-North (m). The
readers return whole logs as series of arrays (:class:`DvlSeries`, ...), one row per log row. Sensor
mountings are applied by the consumers (``slam.model.motion``), from ``datasets.config``.
The sonar beam record is :class:`sonar.beam.SonarBeam`.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from sonar.beam import FloatArray, SonarBeam

__all__ = [
    "DvlVelocity",
    "Attitude",
    "GpsFix",
    "SonarBeam",
    "Record",
    "DvlSeries",
    "AttitudeSeries",
    "GpsSeries",
]


@dataclass(frozen=True)
class DvlVelocity:
    """Bottom-track velocity of the DVL in its own frame (x, y right-handed, z up).

    Attributes
    ----------
    t : float
        Unix time (s).
    vx_mps, vy_mps : float
        Velocity over ground in the DVL frame (m/s).
    valid : bool
        The DVL's bottom-lock flag (``bottomVelStatus == 1``).
    heading_rad : float
        The DVL's internal compass, converted to yaw CCW from East of the DVL x axis (rad);
        NaN when the log has none.
    """

    t: float
    vx_mps: float
    vy_mps: float
    valid: bool
    heading_rad: float = float("nan")


@dataclass(frozen=True)
class Attitude:
    """Heading of the AHRS frame (yaw CCW from East, rad) and its z rate (rad/s, CCW)."""

    t: float
    yaw_rad: float
    yaw_rate_radps: float = 0.0


@dataclass(frozen=True)
class GpsFix:
    """A GPS position in local East-North (m), origin at the first fix of the run."""

    t: float
    east_m: float
    north_m: float


Record = SonarBeam | DvlVelocity | Attitude | GpsFix


# -- whole logs as arrays (what the readers return) ------------------------------------------


@dataclass(frozen=True)
class DvlSeries:
    """DVL bottom-track velocities in the DVL frame; see :class:`datasets.records.DvlVelocity`."""

    t: FloatArray
    v_mps: FloatArray  # (N, 2) vx, vy in the DVL frame
    valid: np.ndarray  # (N,) bool, bottom lock
    heading_rad: FloatArray  # (N,) DVL compass as yaw CCW from East of the DVL x axis
    path: Path | None = None  # the log it was read from (for messages)

    def records(self) -> list[DvlVelocity]:
        return [
            DvlVelocity(float(t), float(v[0]), float(v[1]), bool(ok), float(h))
            for t, v, ok, h in zip(self.t, self.v_mps, self.valid, self.heading_rad, strict=True)
        ]


@dataclass(frozen=True)
class AttitudeSeries:
    """AHRS yaw of its own frame (CCW from East, rad) and yaw rate (CCW, rad/s)."""

    t: FloatArray
    yaw_rad: FloatArray
    yaw_rate_radps: FloatArray
    path: Path | None = None  # the log it was read from (for messages)

    def records(self) -> list[Attitude]:
        return [
            Attitude(float(t), float(y), float(r))
            for t, y, r in zip(self.t, self.yaw_rad, self.yaw_rate_radps, strict=True)
        ]


@dataclass(frozen=True)
class GpsSeries:
    """GPS positions in local East-North (m), origin at ``origin_lat_lon_deg`` (the first fix).

    ``fix`` flags the rows with a position fix (None: all); rows without one (status 0, or the
    receiver's 0/0 placeholder) are kept by the reader and dropped by :mod:`datasets.gates`.
    """

    t: FloatArray
    en_m: FloatArray  # (N, 2)
    origin_lat_lon_deg: tuple[float, float]
    fix: np.ndarray | None = None  # (N,) bool
    path: Path | None = None  # the log it was read from (for messages)

    def records(self) -> list[GpsFix]:
        return [
            GpsFix(float(t), float(p[0]), float(p[1]))
            for t, p in zip(self.t, self.en_m, strict=True)
        ]
