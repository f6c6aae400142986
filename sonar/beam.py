"""The mechanically scanned imaging sonar (MSIS): one beam, the head settings, sensor mountings."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt

from sonarslam.settings import bounded, check_fields, one_of

__all__ = [
    "FloatArray",
    "SonarBeam",
    "SonarHead",
    "Mounting",
    "bin_range_m",
    "beam_bin_size_m",
    "intensities_problem",
    "MAX_BINS",
    "MIN_STEP_RAD",
    "ASSUMED_MOUNTING_SOURCE",
]

#: The project's float array type (``features.geometry`` re-exports it).
FloatArray = npt.NDArray[np.float64]


def intensities_problem(intensities: npt.ArrayLike) -> str | None:
    """Why ``intensities`` are not a beam's bins, or None: they must be uint8 echo strengths
    0-255 (the one place of this rule). Floats 0-1 would be thresholded as all but empty, and
    the front end would find no line, without a word.

    Parameters
    ----------
    intensities : array_like, shape (..., n_bins)

    Returns
    -------
    str or None
        ``"must be uint8 echo strengths 0-255, got float64 ..."`` with the fix, to follow the
        parameter's name in the caller's error; None when they are uint8.
    """
    dtype = np.asarray(intensities).dtype
    if dtype == np.uint8:
        return None
    if np.issubdtype(dtype, np.floating):
        fix = "floats scaled 0-1? np.round(x * 255).astype(np.uint8)"
    else:
        fix = "x.astype(np.uint8) if they are 0-255"
    return f"must be uint8 echo strengths 0-255, got {dtype} ({fix})"


def bin_range_m(bin_index: npt.ArrayLike, bin_size_m: npt.ArrayLike) -> FloatArray:
    """Range (m) of 0-based bin indices: ``(i + 1) * bin_size_m`` (the one place of this rule;
    bin 500 of the marina's 0.1 m bins is at 50.0 m)."""
    return (np.asarray(bin_index, dtype=np.float64) + 1.0) * np.asarray(bin_size_m, np.float64)


#: Largest echo range offset of a head (m), either sign: an echo is kept metres, not tens of
#: metres, behind its surface.
MAX_RANGE_OFFSET_M = 10.0
#: Largest lever arm of a sensor mounting, per axis (m): a sensor sits on the vehicle, within
#: metres of its body origin; a larger number is a unit slip (``x_m = 30`` for 30 cm), which
#: would otherwise pass as a sonar placed tens of metres away.
MAX_LEVER_M = 10.0
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

    n_bins: int = bounded(500, 1, MAX_BINS)
    bin_size_m: float = bounded(0.1, 0.0, np.inf, low_open=True, high_open=True)
    step_rad: float = bounded(float(np.deg2rad(1.8)), MIN_STEP_RAD, np.pi, high_open=True)
    beam_width_rad: float = bounded(
        float(np.deg2rad(3.0)), 0.0, np.pi / 2, low_open=True, high_open=True
    )
    angle_sense: int = one_of(-1, -1, 1)
    range_offset_m: float = bounded(0.0, -MAX_RANGE_OFFSET_M, MAX_RANGE_OFFSET_M)

    def __post_init__(self) -> None:
        check_fields(self)
        if not abs(self.range_offset_m) < self.n_bins * self.bin_size_m:
            raise ValueError(
                f"SonarHead.range_offset_m must be finite and inside the range, got {self.range_offset_m}"
            )

    @property
    def range_max_m(self) -> float:
        """Range of the last bin (m)."""
        return self.n_bins * self.bin_size_m

    def bin_range_m(
        self, bin_index: npt.ArrayLike, bin_size_m: npt.ArrayLike | None = None
    ) -> FloatArray:
        """Range (m) of the surface behind 0-based bin indices: :func:`bin_range_m` less
        ``range_offset_m``; of bins of ``bin_size_m`` (m, a beam's own: a scalar, or one per
        index) when given, else of the head's."""
        size = self.bin_size_m if bin_size_m is None else bin_size_m
        return bin_range_m(bin_index, size) - self.range_offset_m

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


#: The source of a mounting nobody gave (the identity by default). A ``sonarslam.toml`` that
#: writes it keeps it an assumption: the readers warn of it as of a mounting left out
#: (:attr:`Mounting.assumed`).
ASSUMED_MOUNTING_SOURCE = "identity: assumed, never given"
#: The same marker as written before it said so (``sonarslam calibrate --write`` wrote it).
_OLD_ASSUMED_SOURCE = "identity"


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
        Where the numbers come from (calibration method, drawing, ...);
        :data:`ASSUMED_MOUNTING_SOURCE` for a mounting nobody gave.
    """

    x_m: float = bounded(0.0, -MAX_LEVER_M, MAX_LEVER_M)
    y_m: float = bounded(0.0, -MAX_LEVER_M, MAX_LEVER_M)
    yaw_rad: float = bounded(0.0, -2.0 * np.pi, 2.0 * np.pi)
    source: str = ASSUMED_MOUNTING_SOURCE

    def __post_init__(self) -> None:
        check_fields(self)

    @property
    def assumed(self) -> bool:
        """True for a mounting nobody gave: its source is :data:`ASSUMED_MOUNTING_SOURCE` (or
        the bare ``"identity"`` older files hold), whether it came from the defaults or from a
        ``sonarslam.toml`` that wrote the assumption down."""
        return self.source in (ASSUMED_MOUNTING_SOURCE, _OLD_ASSUMED_SOURCE)

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
        Echo intensity per bin, 0-255, nearest bin first (bin ``i`` at
        ``(i + 1) * bin_size_m``, :func:`bin_range_m`); another dtype is refused (ValueError,
        :func:`intensities_problem`). Bins far-first are not detected: every wall would be
        put at the wrong range. Beams that were thresholded before they reached us (the marina
        keyframes) carry 255 for the bins that passed and 0 elsewhere.
    thresholded : bool
        True when ``intensities`` is such a 0/255 mask rather than raw echo strength.
    bin_size_m : float or None
        The beam's own range step between bins (m), when its log changes range (a Ping
        Viewer log's segments); None: the head's (:func:`beam_bin_size_m`).
    """

    t: float
    transducer_angle_rad: float
    intensities: npt.NDArray[np.uint8] = field(repr=False)
    thresholded: bool = False
    bin_size_m: float | None = None

    def __post_init__(self) -> None:
        problem = intensities_problem(self.intensities)
        if problem is not None:
            raise ValueError(f"SonarBeam.intensities {problem}, at t={self.t}")
        if self.bin_size_m is not None and not 0.0 < self.bin_size_m < np.inf:
            raise ValueError(f"SonarBeam.bin_size_m must be a positive range (m), at t={self.t}")


def beam_bin_size_m(beam: SonarBeam, head: SonarHead) -> float:
    """The range step between ``beam``'s bins (m): its own (a log whose range changes), else
    the head's. Every consumer of a beam's bins takes its bin size here."""
    return head.bin_size_m if beam.bin_size_m is None else beam.bin_size_m
