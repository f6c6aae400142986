"""The mechanically scanned imaging sonar (MSIS): one beam, the head settings, sensor mountings."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt

__all__ = [
    "FloatArray",
    "SonarBeam",
    "SonarHead",
    "Mounting",
    "bin_range_m",
    "MAX_BINS",
    "MIN_STEP_RAD",
]

#: The project's float array type (``features.geometry`` re-exports it).
FloatArray = npt.NDArray[np.float64]


def bin_range_m(bin_index: npt.ArrayLike, bin_size_m: float) -> FloatArray:
    """Range (m) of 0-based bin indices: ``(i + 1) * bin_size_m`` (the one place of this rule;
    bin 500 of the marina's 0.1 m bins is at 50.0 m)."""
    return (np.asarray(bin_index, dtype=np.float64) + 1.0) * bin_size_m


#: Largest lever arm of a sensor mounting (m).
MAX_LEVER_M = 100.0
#: Most bins per beam of a head (MSIS heads log up to ~1,500): more is a corrupt setting that
#: would allocate a scan of ``n_bins x beams`` for nothing.
MAX_BINS = 10_000
#: Smallest mechanical step (rad): 0.1 deg, 3,600 beams per turn (the finest MSIS step is 0.225).
MIN_STEP_RAD = float(np.deg2rad(0.1))


@dataclass(frozen=True)
class SonarHead:
    """Settings of the sonar head.

    Bin ``i`` (0-based) of a beam is the echo at range ``(i + 1) * bin_size_m``, as in the marina
    keyframes (bin 500 at 50.0 m), less the head's calibrated ``range_offset_m`` (how far behind
    the reflecting surface the echo that is kept lies: the peak of a raw echo, the first bin of
    a thresholded one): :meth:`bin_range_m` is the range of the surface, the logs' bin indices
    keep the raw convention. The transducer angle ``a`` of a beam, as logged, is turned
    into a bearing in the right-handed sonar frame as ``angle_sense * a``; ``angle_sense = -1``
    for a head whose logged angle grows clockwise seen from above (the marina's Miniking).

    Attributes
    ----------
    n_bins : int
        Bins per beam.
    bin_size_m : float
        Range step between bins (m).
    step_rad : float
        Mechanical step between beams (rad).
    beam_width_rad : float
        Horizontal beam width alpha (rad), 3 deg for a Miniking.
    angle_sense : int
        +1 or -1, see above.
    range_offset_m : float
        The echo's range minus the surface's (m), subtracted from every bin's range.
    """

    n_bins: int = 500
    bin_size_m: float = 0.1
    step_rad: float = float(np.deg2rad(1.8))
    beam_width_rad: float = float(np.deg2rad(3.0))
    angle_sense: int = -1
    range_offset_m: float = 0.0

    def __post_init__(self) -> None:
        if not 0 < self.n_bins <= MAX_BINS:
            raise ValueError(f"SonarHead.n_bins must be in 1-{MAX_BINS}, got {self.n_bins}")
        if not 0.0 < self.bin_size_m < np.inf:
            raise ValueError(f"SonarHead.bin_size_m must be positive, got {self.bin_size_m}")
        if not MIN_STEP_RAD <= self.step_rad < np.pi:
            raise ValueError(
                f"SonarHead.step_rad must be in [{MIN_STEP_RAD:.6f}, pi), got {self.step_rad}"
            )
        if not 0.0 < self.beam_width_rad < np.pi / 2:
            raise ValueError(
                f"SonarHead.beam_width_rad must be in (0, pi/2), got {self.beam_width_rad}"
            )
        if self.angle_sense not in (-1, 1):
            raise ValueError(f"SonarHead.angle_sense must be +1 or -1, got {self.angle_sense}")
        if not abs(self.range_offset_m) < self.n_bins * self.bin_size_m:
            raise ValueError(
                f"SonarHead.range_offset_m must be finite and inside the range, got {self.range_offset_m}"
            )

    @property
    def range_max_m(self) -> float:
        """Range of the last bin (m)."""
        return self.n_bins * self.bin_size_m

    def bin_range_m(self, bin_index: npt.ArrayLike) -> FloatArray:
        """Range (m) of the surface behind 0-based bin indices: :func:`bin_range_m` less
        ``range_offset_m``."""
        return bin_range_m(bin_index, self.bin_size_m) - self.range_offset_m

    def bin_ranges_m(self) -> FloatArray:
        """Range of every bin, shape ``(n_bins,)`` (m)."""
        return self.bin_range_m(np.arange(self.n_bins))

    def range_to_bin(self, range_m: npt.ArrayLike) -> npt.NDArray[np.int64]:
        """Nearest 0-based bin index of ranges (m); not clipped (inverse of :meth:`bin_range_m`)."""
        return np.rint(self.range_to_bin_float(range_m)).astype(np.int64)

    def range_to_bin_float(self, range_m: npt.ArrayLike) -> FloatArray:
        """Fractional 0-based bin index of surface ranges (m), inverse of :meth:`bin_range_m`:
        ``(r + range_offset_m) / bin_size_m - 1``."""
        r = np.asarray(range_m, dtype=np.float64) + self.range_offset_m
        return np.asarray(r / self.bin_size_m - 1.0)

    def bearing_rad(self, transducer_angle_rad: npt.ArrayLike) -> FloatArray:
        """Bearing in the right-handed sonar frame of logged transducer angles (rad)."""
        return np.asarray(self.angle_sense * np.asarray(transducer_angle_rad, dtype=np.float64))


@dataclass(frozen=True)
class Mounting:
    """Pose of a sensor frame in the vehicle body frame (x forward, y left), ``bTs``.

    Attributes
    ----------
    x_m, y_m : float
        Position of the sensor in the body frame (m).
    yaw_rad : float
        Rotation of the sensor frame about the body z axis, counter-clockwise (rad).
    source : str
        Where the numbers come from (calibration method, drawing, ...).
    """

    x_m: float = 0.0
    y_m: float = 0.0
    yaw_rad: float = 0.0
    source: str = "identity"

    def __post_init__(self) -> None:
        for name, value in (("x_m", self.x_m), ("y_m", self.y_m)):  # each named alone
            if not abs(value) <= MAX_LEVER_M:
                raise ValueError(f"{name} must be within +-{MAX_LEVER_M:g} m, got {value}")
        if not abs(self.yaw_rad) <= 2.0 * np.pi:
            raise ValueError(f"Mounting.yaw_rad must be within +-2 pi, got {self.yaw_rad}")

    def as_pose(self) -> FloatArray:
        """``bTs`` as an array ``(x_m, y_m, yaw_rad)``."""
        return np.array([self.x_m, self.y_m, self.yaw_rad], dtype=np.float64)


@dataclass(frozen=True, eq=False)
class SonarBeam:
    """One MSIS beam.

    Attributes
    ----------
    t : float
        Time of the beam (Unix s).
    transducer_angle_rad : float
        Head angle as logged (rad); see :meth:`SonarHead.bearing_rad`.
    intensities : ndarray of uint8, shape (n_bins,)
        Echo intensity per bin, 0-255. Beams that were thresholded before they reached us
        (the marina keyframes) carry 255 for the bins that passed and 0 elsewhere.
    thresholded : bool
        True when ``intensities`` is such a 0/255 mask rather than raw echo strength.
    """

    t: float
    transducer_angle_rad: float
    intensities: npt.NDArray[np.uint8] = field(repr=False)
    thresholded: bool = False
