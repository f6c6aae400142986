"""Absolute trajectory error.

* Against GPS, by the protocol of Mallios et al. 2014 (the marina's published table): at every GPS
  fix inside the trajectory's time span, the distance between the GPS position and the estimate
  interpolated at that time; no alignment of any kind (:func:`ate_against_gps`). Beside it, the
  same after a rigid SE(2) fit of the estimate's positions onto the fixes (``align=True``, as
  ``evo_ape -a``): the shape error, without the start pose and heading that no GPS-free
  estimator observes.
* Against the simulator's truth: the same at every true pose inside the span, optionally after
  a rigid alignment of the estimate onto the truth (:func:`ate_against_truth`, Umeyama 1991 by
  evo), which leaves the shape error only.

Either can be restricted to a time span: the **sonar span** (first to last sonar beam inside the
navigation span, :attr:`sonarslam.datasets.source.Dataset.sonar_span_s`) is where line landmarks can act;
after the sonar stops every method is dead reckoning.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np
from evo.core.geometry import GeometryException, umeyama_alignment

from sonarslam.datasets.records import GpsSeries
from sonarslam.features.geometry import FloatArray, wrap_angle
from sonarslam.slam.io.trajectory import Trajectory

__all__ = [
    "AteResult",
    "HeadingResult",
    "ate_against_gps",
    "ate_against_truth",
    "ate_errors",
    "ate_of_errors",
    "half_split_s",
    "halves",
    "heading_against_truth",
    "rigid_fit",
    "truth_errors",
]


@dataclass(frozen=True)
class AteResult:
    """ATE statistics (m) over ``n`` reference positions."""

    ate_mean_m: float
    ate_sd_m: float
    ate_min_m: float
    ate_max_m: float
    ate_rmse_m: float
    ate_n: int

    def as_dict(self, prefix: str = "ate") -> dict[str, float | int]:
        """``{prefix}_mean_m``, ``{prefix}_sd_m``, ... (``ate_mean_m`` by default)."""
        return {prefix + k[3:]: v for k, v in asdict(self).items()}


def _inside(
    t_s: FloatArray, trajectory: Trajectory, span_s: tuple[float, float] | None
) -> np.ndarray:
    t0, t1 = trajectory.span_s
    if span_s is not None:
        t0, t1 = max(t0, span_s[0]), min(t1, span_s[1])
    return np.asarray((t_s >= t0) & (t_s <= t1))


def rigid_fit(est: FloatArray, ref: FloatArray) -> FloatArray:
    """``est`` (N, 2) moved by the rotation and translation (no scale) that best fit it onto
    ``ref`` in least squares (``evo.core.geometry.umeyama_alignment``, Umeyama 1991). Where
    either set is a single point repeated (a vehicle that did not move), every rotation fits
    equally well and the fit is the translation of the centroids."""
    if est.shape[0] < 2:
        return est
    try:
        r, t, _ = umeyama_alignment(est.T, ref.T, False)
    except GeometryException:  # rank-0 cross-covariance: the rotation is undetermined
        return np.asarray(est - est.mean(axis=0) + ref.mean(axis=0))
    return np.asarray((r @ est.T).T + t)


def ate_errors(
    trajectory: Trajectory,
    gps: GpsSeries,
    span_s: tuple[float, float] | None = None,
    align: bool = False,
) -> tuple[FloatArray, FloatArray]:
    """Times (s) and position errors (m) at the GPS fixes inside the trajectory's span (and
    inside ``span_s`` when given); ``align``: after a rigid fit onto those fixes."""
    inside = _inside(gps.t, trajectory, span_s)
    est = trajectory.poses(gps.t[inside])[:, :2]
    ref = gps.en_m[inside]
    if align:
        est = rigid_fit(est, ref)
    return gps.t[inside], np.hypot(*(est - ref).T)


def half_split_s(span_s: tuple[float, float]) -> float:
    """The time that cuts a span into its two halves (Unix s): its middle. On the marina the
    sonar span's is 1,501 s after its first beam: the first half is where a default may be
    informed by GPS, the second the held-out one (docs/design-decisions.md)."""
    return 0.5 * (span_s[0] + span_s[1])


def halves(t_s: FloatArray, errors_m: FloatArray, split_s: float) -> tuple[AteResult, AteResult]:
    """The statistics of errors at times up to ``split_s`` and after it (ValueError when a half
    has none)."""
    first = np.asarray(t_s) <= split_s
    return ate_of_errors(errors_m[first]), ate_of_errors(errors_m[~first])


def ate_of_errors(errors_m: FloatArray) -> AteResult:
    """The statistics of position errors (m); ValueError when there are none."""
    e = np.asarray(errors_m, dtype=np.float64)
    if e.size == 0:
        raise ValueError("no reference position inside the trajectory's time span")
    return AteResult(
        ate_mean_m=float(e.mean()),
        ate_sd_m=float(e.std(ddof=1)) if e.size > 1 else 0.0,
        ate_min_m=float(e.min()),
        ate_max_m=float(e.max()),
        ate_rmse_m=float(np.sqrt(np.mean(e**2))),
        ate_n=int(e.size),
    )


def ate_against_gps(
    trajectory: Trajectory,
    gps: GpsSeries,
    span_s: tuple[float, float] | None = None,
    align: bool = False,
) -> AteResult:
    """The ATE of ``trajectory`` against ``gps`` (over ``span_s`` when given; ``align``: after a
    rigid SE(2) fit onto the fixes, as ``evo_ape -a``); raises ValueError when no fix is
    inside."""
    return ate_of_errors(ate_errors(trajectory, gps, span_s, align)[1])


@dataclass(frozen=True)
class HeadingResult:
    """Heading error statistics (deg, absolute, wrapped to [0, 180]) over ``n`` true poses."""

    mean_deg: float
    max_deg: float
    n: int


def heading_against_truth(
    trajectory: Trajectory, truth: Trajectory, span_s: tuple[float, float] | None = None
) -> HeadingResult:
    """The heading error of ``trajectory`` at the true poses inside its span (and ``span_s``):
    the mean and max of ``|wrap(yaw - true yaw)|`` (deg). No alignment: beside the ATE as it
    is, it shows a wrong start heading, which no position error shows of a still head (its
    position is given apart from its heading). ValueError when no true pose is inside."""
    inside = _inside(truth.t_s, trajectory, span_s)
    if not np.any(inside):
        raise ValueError("no reference pose inside the trajectory's time span")
    yaw = trajectory.poses(truth.t_s[inside])[:, 2]
    miss = np.abs(np.rad2deg(wrap_angle(yaw - truth.poses_wTb[inside, 2])))
    return HeadingResult(float(miss.mean()), float(miss.max()), int(miss.size))


def truth_errors(
    trajectory: Trajectory,
    truth: Trajectory,
    span_s: tuple[float, float] | None = None,
    align: bool = False,
) -> tuple[FloatArray, FloatArray]:
    """Times (s) and position errors (m) of ``trajectory`` at the true poses inside its span
    (and ``span_s``); ``align``: see :func:`ate_against_truth`."""
    inside = _inside(truth.t_s, trajectory, span_s)
    ref = truth.poses_wTb[inside, :2]
    est = trajectory.poses(truth.t_s[inside])[:, :2]
    if align:
        est = rigid_fit(est, ref)
    return truth.t_s[inside], np.hypot(*(est - ref).T)


def ate_against_truth(
    trajectory: Trajectory,
    truth: Trajectory,
    span_s: tuple[float, float] | None = None,
    align: bool = False,
) -> AteResult:
    """The ATE of ``trajectory`` at the true poses inside its span (and ``span_s``).

    ``align``: first a rigid (rotation and translation, no scale) least-squares alignment of
    the estimate's positions onto the true ones (``evo.core.geometry.umeyama_alignment``).
    """
    return ate_of_errors(truth_errors(trajectory, truth, span_s, align)[1])
