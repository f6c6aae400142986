"""Typed records of the merged, time-ordered sensor stream.

Frames and units are fixed in the readers: yaw angles are counter-clockwise from East (rad),
velocities are in the sensor's own frame (m/s), positions are local East-North (m). Sensor
mountings are applied by the consumers (``slam.model.motion``), from ``datasets.config``.
The sonar beam record is :class:`sonar.beam.SonarBeam`.
"""

from __future__ import annotations

from dataclasses import dataclass

from sonar.beam import SonarBeam

__all__ = ["DvlVelocity", "Attitude", "GpsFix", "SonarBeam", "Record"]


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
