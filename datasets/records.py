"""Typed records of the merged, time-ordered sensor stream.

Frames and units are fixed in the readers: yaw angles are counter-clockwise from East (rad),
velocities are in the sensor's own frame (m/s), positions are local East-North (m). The
readers return whole logs as series of arrays (:class:`DvlSeries`, ...), one row per log row. Sensor
mountings are applied by the consumers (``slam.model.motion``), from ``datasets.config``.
The sonar beam record is :class:`sonarslam.sonar.beam.SonarBeam`.
"""

from __future__ import annotations

from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import overload

import numpy as np
import numpy.typing as npt

from sonarslam.sonar.beam import FloatArray, SonarBeam, intensities_problem

__all__ = [
    "DvlVelocity",
    "Attitude",
    "GpsFix",
    "SonarBeam",
    "Record",
    "DvlSeries",
    "AttitudeSeries",
    "GpsSeries",
    "BeamSeries",
    "SonarSegment",
    "farthest_segment",
    "STEP_TOLERANCE",
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
    yaw_rate_rad_per_s: float = 0.0


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
    """DVL bottom-track velocities in the DVL frame; see :class:`sonarslam.datasets.records.DvlVelocity`."""

    t: FloatArray
    v_mps: FloatArray  # (N, 2) vx, vy in the DVL frame
    valid: np.ndarray  # (N,) bool, bottom lock
    heading_rad: FloatArray  # (N,) DVL compass as yaw CCW from East of the DVL x axis
    path: Path | None = None  # the log it was read from (for messages)
    #: the velocities' quantum when the log rounds them (m/s; QGroundControl's CSV export: 0.1,
    #: so a vehicle under 0.05 m/s per axis reads exactly 0); 0: a DVL's own, fine resolution
    resolution_mps: float = 0.0

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
    yaw_rate_rad_per_s: FloatArray
    path: Path | None = None  # the log it was read from (for messages)

    def records(self) -> list[Attitude]:
        return [
            Attitude(float(t), float(y), float(r))
            for t, y, r in zip(self.t, self.yaw_rad, self.yaw_rate_rad_per_s, strict=True)
        ]


@dataclass(frozen=True)
class GpsSeries:
    """GPS positions in local East-North (m), origin at ``origin_lat_lon_deg`` (the first fix).

    ``fix`` flags the rows with a position fix (None: all); rows without one (status 0, or the
    receiver's 0/0 placeholder) are kept by the reader and dropped by :mod:`sonarslam.datasets.gates`.
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


@dataclass(frozen=True)
class SonarSegment:
    """A stretch of a log's beams of one head setting: its range, bin size, gain and sector
    (a Ping Viewer log changes them as the user does, :mod:`sonarslam.datasets.ping360`).

    Attributes
    ----------
    t0_s, t1_s : float
        Its first and last beam's time (Unix s).
    beams : int
    n_bins : int
        Samples of each of its beams.
    bin_size_m : float
        Range step between its bins (m).
    setting : str
        The rest of the setting in words (the sample period, the gain, the sector).
    """

    t0_s: float
    t1_s: float
    beams: int
    n_bins: int
    bin_size_m: float
    setting: str

    @property
    def range_m(self) -> float:
        """Range of its last bin (m)."""
        return self.n_bins * self.bin_size_m


def farthest_segment(segments: Sequence[SonarSegment]) -> SonarSegment:
    """The segment whose range reaches farthest (of those, the one of most beams): the head of
    a log of several (its bin size is the head's, the Hough grid spans its range; the rows are
    as wide as the most bins of any)."""
    return max(segments, key=lambda g: (g.range_m, g.beams))


#: A configured step between beams more than this share off the beams' own is another head
#: setting (a Micron's or a Ping360's steps differ by factors of two), not the beams' jitter.
STEP_TOLERANCE = 0.1


class BeamSeries(Sequence[SonarBeam]):
    """The sonar beams of a run as arrays: one row per beam, ``(N, n_bins)`` uint8 intensities.

    A sequence of :class:`sonarslam.sonar.beam.SonarBeam`: ``beams[i]`` is a beam (its intensities a view
    of the row), ``beams[a:b]`` and :meth:`between` are series over views of the same arrays.
    A beam as a Python object costs ~0.5 kB beside its bins; held as rows, a run of 460,000
    beams of 500 bins takes its 230 MB of bins and little more.

    Parameters
    ----------
    t_s : ndarray, shape (N,)
        Beam times (Unix s), non-decreasing.
    transducer_angle_rad : ndarray, shape (N,)
        Head angles as logged (rad).
    intensities : ndarray of uint8, shape (N, n_bins)
    thresholded : bool
        The rows are 0/255 masks (the marina keyframes), not raw echo strength.
    bin_size_m : ndarray, shape (N,), optional
        Each beam's own range step between bins (m), for a log whose range changes (its
        segments, :class:`SonarSegment`; a beam of fewer bins than the row is padded with
        zeros); None: every beam has the head's (``SonarHead.bin_size_m``).
    """

    __slots__ = ("t_s", "transducer_angle_rad", "intensities", "thresholded", "bin_size_m")

    def __init__(
        self,
        t_s: FloatArray,
        transducer_angle_rad: FloatArray,
        intensities: npt.NDArray[np.uint8],
        thresholded: bool = False,
        bin_size_m: FloatArray | None = None,
    ) -> None:
        n = t_s.shape[0]
        if t_s.shape != (n,) or transducer_angle_rad.shape != (n,) or intensities.ndim != 2:
            raise ValueError(
                f"t_s (N,), angles (N,), intensities (N, n_bins) expected, got {t_s.shape},"
                f" {transducer_angle_rad.shape}, {intensities.shape}"
            )
        if intensities.shape[0] != n:
            raise ValueError(f"intensities must be ({n}, n_bins), got {intensities.shape}")
        problem = intensities_problem(intensities)
        if problem is not None:
            raise ValueError(f"BeamSeries intensities {problem}")
        if bin_size_m is not None and (
            bin_size_m.shape != (n,) or not np.all(np.isfinite(bin_size_m) & (bin_size_m > 0))
        ):
            raise ValueError(f"bin_size_m must be ({n},) of positive finite ranges (m)")
        self.t_s = t_s
        self.transducer_angle_rad = transducer_angle_rad
        self.intensities = intensities
        self.thresholded = thresholded
        self.bin_size_m = bin_size_m

    @classmethod
    def empty(cls, n_bins: int, thresholded: bool = False) -> BeamSeries:
        return cls(np.zeros(0), np.zeros(0), np.zeros((0, n_bins), dtype=np.uint8), thresholded)

    @classmethod
    def of(cls, beams: Sequence[SonarBeam]) -> BeamSeries:
        """A series of beam objects (all of one bin count and kind)."""
        if isinstance(beams, BeamSeries):
            return beams
        if not beams:
            return cls.empty(0)
        own = [b.bin_size_m for b in beams]
        if any(m is not None for m in own) and any(m is None for m in own):
            raise ValueError("beams with their own bin_size_m and beams without cannot be mixed")
        return cls(
            np.array([b.t for b in beams], dtype=np.float64),
            np.array([b.transducer_angle_rad for b in beams], dtype=np.float64),
            np.stack([b.intensities for b in beams]),  # uint8: each beam checked its own
            bool(beams[0].thresholded),
            None if own[0] is None else np.array(own, dtype=np.float64),
        )

    def __len__(self) -> int:
        return int(self.t_s.shape[0])

    @overload
    def __getitem__(self, i: int) -> SonarBeam: ...

    @overload
    def __getitem__(self, i: slice) -> BeamSeries: ...

    def __getitem__(self, i: int | slice) -> SonarBeam | BeamSeries:
        own = self.bin_size_m
        if isinstance(i, slice):
            return BeamSeries(
                self.t_s[i],
                self.transducer_angle_rad[i],
                self.intensities[i],
                self.thresholded,
                None if own is None else own[i],
            )
        return SonarBeam(
            t=float(self.t_s[i]),
            transducer_angle_rad=float(self.transducer_angle_rad[i]),
            intensities=self.intensities[i],
            thresholded=self.thresholded,
            bin_size_m=None if own is None else float(own[i]),
        )

    def __iter__(self) -> Iterator[SonarBeam]:
        for i in range(len(self)):
            yield self[i]

    def between(self, t0_s: float, t1_s: float) -> BeamSeries:
        """The beams with ``t0_s <= t <= t1_s`` (a view)."""
        a = int(np.searchsorted(self.t_s, t0_s, side="left"))
        b = int(np.searchsorted(self.t_s, t1_s, side="right"))
        return self[a:b]

    def shifted(self, offset_s: float) -> BeamSeries:
        """The same beams ``offset_s`` later (a clock offset); the bins are shared."""
        return BeamSeries(
            self.t_s + offset_s,
            self.transducer_angle_rad,
            self.intensities,
            self.thresholded,
            self.bin_size_m,
        )

    def step_rad(self, min_steps: int = 20) -> float | None:
        """The head's step between beams as the beams show it (rad): the median of the
        magnitudes of the successive angle changes, wrapped, that are not zero (a repeated
        angle, a sector scan's turn-about); None over fewer than ``min_steps`` of them."""
        a = self.transducer_angle_rad
        d = np.abs(np.angle(np.exp(1j * np.diff(a))))
        d = d[d > 1e-9]
        return float(np.median(d)) if d.size >= min_steps else None
