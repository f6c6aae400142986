"""A dataset's start pose, motion noise and the pose sources that need no estimator.

GPS + AHRS (``gps``), dead reckoning (``dr``) and the simulator's truth (``truth``) all return a
:class:`sonarslam.slam.io.trajectory.Trajectory`, which implements the front end's
:class:`sonarslam.features.pose_source.PoseSource` (:data:`POSE_SOURCES`, :func:`pose_source_by_name`).
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Callable

import numpy as np

from sonarslam.datasets.errors import DataWarning
from sonarslam.datasets.gates import DVL_MIN_SPEED_MPS, dvl_speed_quantiles
from sonarslam.datasets.records import GpsSeries
from sonarslam.datasets.source import Dataset
from sonarslam.features.geometry import FloatArray
from sonarslam.slam.eval.truth import truth_trajectory
from sonarslam.slam.io.trajectory import Trajectory
from sonarslam.slam.model.motion import body_velocity, body_yaw, dead_reckoning
from sonarslam.slam.model.noise import MotionNoise, dvl_scatter
from sonarslam.sonar.beam import Mounting

__all__ = [
    "warn_dvl_sigma",
    "dvl_body_velocities",
    "mounting_yaw_said",
    "DVL_SIGMA_OVER_SCATTER_MAX",
    "motion_noise",
    "start_pose",
    "start_pose_origin",
    "gps_ahrs_trajectory",
    "dead_reckoning_trajectory",
    "dvl_quality",
    "POSE_SOURCES",
    "pose_source_by_name",
]


def motion_noise(dataset: Dataset) -> MotionNoise:
    """The motion-model noise from the dataset's ``[noise]`` settings; a DVL or AHRS sample is
    stale after the sensor's gap threshold (:mod:`sonarslam.datasets.gates`)."""
    n = dataset.config.noise
    gaps = dataset.report.gaps
    inf = float("inf")
    return MotionNoise.from_config(
        n,
        dvl_stale_s=gaps["dvl"].threshold_s if "dvl" in gaps else inf,
        ahrs_stale_s=gaps["ahrs"].threshold_s if "ahrs" in gaps else inf,
    )


def dvl_quality(dataset: Dataset) -> dict[str, float]:
    """How the DVL behaved (for ``metrics.json`` and ``sonarslam info``).

    Quantiles (10, 50, 90, 99 %) of its own scatter (:func:`sonarslam.slam.model.noise.dvl_scatter`, m/s,
    over ``[noise] dvl_scatter_window_s``, 60 s when that is off); the time its scatter stayed
    above the nominal one, when :func:`sonarslam.slam.model.noise.dvl_sample_sigma` added the excess as noise
    (s; 0 when off), and the first such time after the start of the logs (s, -1 if none).
    The median and 90th percentile of its horizontal speed over the locked rows (m/s,
    :func:`sonarslam.datasets.gates.dvl_speed_quantiles`; NaN without one).
    """
    noise = motion_noise(dataset)
    dvl = dataset.dvl
    t, v = dvl.t[dvl.valid], dvl.v_mps[dvl.valid]
    out = {f"dvl_speed_p{p}_mps": q for p, q in dvl_speed_quantiles(dvl, (50, 90)).items()}
    out.update({f"dvl_scatter_p{p}_mps": float("nan") for p in (10, 50, 90, 99)})
    out.update({"dvl_excess_s": 0.0, "dvl_excess_from_s": -1.0})
    if t.size < 2:
        return out
    scatter = dvl_scatter(t, v, noise.dvl_scatter_window_s or 60.0)
    for p in (10, 50, 90, 99):
        out[f"dvl_scatter_p{p}_mps"] = float(np.percentile(scatter, p))
    if noise.dvl_scatter_window_s > 0.0:
        over = scatter[1:] > noise.dvl_nominal_scatter_mps
        out["dvl_excess_s"] = float(np.diff(t)[over].sum())
        if over.any():
            out["dvl_excess_from_s"] = float(t[1:][over][0] - dataset.nav_span_s[0])
    return out


def dvl_body_velocities(dataset: Dataset) -> FloatArray:
    """The locked DVL rows' velocities in the body frame, shape (V, 2) (m/s): through the DVL's
    mounting, without the lever arm's turning term (which way the vehicle travels: the
    ``travel`` check, :func:`sonarslam.slam.eval.health.travel_judgement`)."""
    dvl = dataset.dvl
    return body_velocity(dvl.v_mps[dvl.valid], dataset.config.dvl_mounting)


def mounting_yaw_said(sensor: str, mounting: Mounting) -> str:
    """``"[mounting.<sensor>] yaw_deg = <deg> (<source>)"``: a mounting as in force, for a
    message that blames it."""
    return f"[mounting.{sensor}] yaw_deg = {math.degrees(mounting.yaw_rad):g} ({mounting.source})"


#: ``[noise] dvl_sigma_mps`` more than this many times the DVL's measured scatter (the median
#: of :func:`dvl_quality`'s) is warned of. The scatter (the Allan deviation at one sample, the
#: vehicle's accelerations included) bounds the DVL's white noise from above, and the sigma is
#: the part of that noise that drifts, at most about the scatter; ten times above claims an error
#: the samples do not show and weighs the DVL 100 times less (in variance) against the sonar and
#: the AHRS than its data say (docs/bad-input.md gives the figures).
DVL_SIGMA_OVER_SCATTER_MAX = 10.0


def warn_dvl_sigma(dataset: Dataset, quality: dict[str, float] | None = None) -> str:
    """Warn when ``[noise] dvl_sigma_mps`` lies far above the DVL's measured scatter
    (:data:`DVL_SIGMA_OVER_SCATTER_MAX`); the warning's text, or "" when it does not.
    ``quality`` is :func:`dvl_quality`'s (computed when not given)."""
    sigma = float(dataset.config.noise.dvl_sigma_mps)
    q = quality or dvl_quality(dataset)
    scatter = q["dvl_scatter_p50_mps"]
    if not (scatter > 0.0 and sigma > DVL_SIGMA_OVER_SCATTER_MAX * scatter):
        return ""
    if q["dvl_speed_p90_mps"] < DVL_MIN_SPEED_MPS:
        return ""  # the velocities' unit is wrong, and said when read: the scatter shrank too
    message = (
        f"{dataset.root}: [noise] dvl_sigma_mps = {sigma:g} m/s ({dataset.calibration}) is"
        f" {sigma / scatter:.0f} times the DVL's own scatter (median {scatter:.3g} m/s over"
        f" {dataset.config.noise.dvl_scatter_window_s or 60.0:g} s windows, `sonarslam info`),"
        f" more than the {DVL_SIGMA_OVER_SCATTER_MAX:g} times a drift of the DVL could explain:"
        " the estimators weigh the DVL far less than its data say (a value meant in other"
        " units? or, if the scatter is implausibly small, DVL velocities in another unit)"
    )
    warnings.warn(message, DataWarning, stacklevel=2)
    return message


def _require_gps(dataset: Dataset) -> GpsSeries:
    if dataset.gps is None:
        raise ValueError(
            f"{dataset.root}: no GPS (*_DGPS.log or a NavSatFix topic), so no GPS trajectory:"
            " take --poses dr"
        )
    return dataset.gps


def _still_pose(dataset: Dataset) -> FloatArray:
    """The pose of a still head (:attr:`Dataset.still`): ``--start``'s, the yaw 0 (East)
    when not given, else the origin heading East."""
    x, y, yaw = dataset.start_enu if dataset.start_enu is not None else (0.0, 0.0, 0.0)
    return np.array([x, y, yaw if np.isfinite(yaw) else 0.0])


def start_pose_origin(dataset: Dataset) -> str:
    """Where :func:`start_pose` takes the start from, in words (``metrics.json start_pose``)."""
    if dataset.still:
        x, y, yaw = _still_pose(dataset)
        given = "given (--start)" if dataset.start_enu is not None else "not given (--start)"
        return (
            f"no navigation: a still head at ({x:g}, {y:g}) m heading {math.degrees(yaw):g} deg"
            f" CCW from East, {given}, the whole log long"
        )
    if dataset.start_enu is not None:
        x, y, _ = dataset.start_enu
        where = "the first GPS fix's time" if dataset.gps is not None else "the navigation's start"
        return f"given (--start {x:g},{y:g}) at {where}, heading from the AHRS"
    if dataset.gps is not None:
        return "the first GPS fix inside the navigation span, heading from the AHRS"
    return "no GPS: the origin at the navigation's start, heading from the AHRS"


def start_pose(dataset: Dataset) -> tuple[float, FloatArray, FloatArray]:
    """Start time, pose and covariance of every estimator (the ATE protocol).

    With GPS, the start is the first GPS fix inside the navigation span; its position is that
    fix, its yaw the heading sensor's (through the AHRS mounting). Without GPS, the start is the
    start of the navigation span (DVL and AHRS both logging) at the origin of the local frame,
    its yaw the heading sensor's. A position the user gave (:attr:`Dataset.start_enu`,
    ``--start``) replaces the position at the same time; a heading given with it must agree with
    the AHRS's within 3 ``ahrs_sigma_deg`` (``ValueError`` otherwise): the heading is always the
    AHRS's. The covariance is
    ``diag(gps_sigma_m^2, gps_sigma_m^2, ahrs_sigma^2)`` in every case. A still head
    (:attr:`Dataset.still`, no navigation) starts at its pose (``--start``), exactly: its
    covariance is zero.
    """
    t_nav0, t_nav1 = dataset.nav_span_s
    if dataset.still:
        return float(t_nav0), _still_pose(dataset), np.zeros((3, 3))
    if dataset.gps is not None:
        gps = dataset.gps
        inside = np.flatnonzero((gps.t >= t_nav0) & (gps.t <= t_nav1))
        if inside.size == 0:
            raise ValueError(f"{dataset.root}: no GPS fix inside the navigation span")
        i = int(inside[0])
        t0 = float(gps.t[i])
        xy = (float(gps.en_m[i, 0]), float(gps.en_m[i, 1]))
    else:
        t0, xy = float(t_nav0), (0.0, 0.0)
    yaw_a = np.interp(t0, dataset.attitude.t, np.unwrap(dataset.attitude.yaw_rad))
    psi = float(body_yaw(yaw_a, dataset.config.ahrs_mounting, dataset.config.ahrs_deviation_rad))
    sigma_gps = dataset.config.noise.gps_sigma_m
    sigma_yaw = np.deg2rad(dataset.config.noise.ahrs_sigma_deg)
    if dataset.start_enu is not None:
        xy = (dataset.start_enu[0], dataset.start_enu[1])
        given = dataset.start_enu[2]
        miss = (given - psi + np.pi) % (2.0 * np.pi) - np.pi
        if np.isfinite(given) and abs(miss) > 3.0 * sigma_yaw:
            # every estimator takes its heading from the AHRS: a start heading that disagrees
            # with it is a wrong AHRS mounting (or a wrong --start), never overridden here
            raise ValueError(
                f"{dataset.root}: --start heading {np.rad2deg(given):.1f} deg differs from the"
                f" AHRS's {np.rad2deg(psi):.1f} deg at the start by more than 3 sigma"
                f" ({3.0 * np.rad2deg(sigma_yaw):.1f} deg): the heading comes from the AHRS;"
                " set [mounting.ahrs] yaw_deg, or leave the heading out (--start X,Y)"
            )
    cov = np.diag([sigma_gps**2, sigma_gps**2, sigma_yaw**2])
    return t0, np.array([xy[0], xy[1], psi]), cov


def dead_reckoning_trajectory(dataset: Dataset) -> Trajectory:
    """Dead reckoning of a ``dataset`` (DVL velocities rotated by the AHRS heading) over its
    navigation span, from the ATE protocol's start pose (:func:`start_pose`: the first GPS fix
    with the AHRS heading).

    Parameters
    ----------
    dataset : Dataset
        An opened dataset; its ``[noise]`` settings give the motion noise
        (:func:`motion_noise`).

    Returns
    -------
    Trajectory
        Body poses ``wTb`` ``(x_m, y_m, yaw_rad)`` in the readers' local East-North frame with
        their covariances, on the AHRS timeline; a
        :class:`sonarslam.features.pose_source.PoseSource`.

    Raises
    ------
    ValueError
        No GPS fix inside the navigation span, or a given start heading that disagrees with the
        AHRS (:func:`start_pose`).

    Notes
    -----
    A still head (:attr:`Dataset.still`, a sonar log without navigation) has no motion to
    reckon: its trajectory is its pose (:func:`start_pose`) at every second of the beams'
    span, without a covariance (the pose is given, not estimated: the lines' covariances are
    the sonar's alone, as with any pose source that has none; and no NEES is taken of it).
    """
    t0, pose0, cov0 = start_pose(dataset)
    if dataset.still:
        t1 = dataset.nav_span_s[1]
        t = np.unique(np.r_[np.arange(t0, t1, 1.0), t1])
        return Trajectory(t, np.tile(pose0, (t.size, 1)), None)
    return dead_reckoning(
        dataset.attitude,
        dataset.dvl,
        dataset.config.dvl_mounting,
        dataset.config.ahrs_mounting,
        pose0,
        cov0,
        t0,
        dataset.nav_span_s[1],
        motion_noise(dataset),
        dataset.config.ahrs_deviation_rad,
        dataset.config.yaw_rate_source,
    )


def gps_ahrs_trajectory(dataset: Dataset) -> Trajectory:
    """GPS positions (interpolated) with the AHRS body heading, on the AHRS timeline."""
    gps = _require_gps(dataset)
    t0, t1 = (
        max(dataset.nav_span_s[0], float(gps.t[0])),
        min(dataset.nav_span_s[1], float(gps.t[-1])),
    )
    att = dataset.attitude
    keep = (att.t >= t0) & (att.t <= t1)
    t = att.t[keep]
    psi = body_yaw(
        att.yaw_rad[keep], dataset.config.ahrs_mounting, dataset.config.ahrs_deviation_rad
    )
    xy = np.column_stack([np.interp(t, gps.t, gps.en_m[:, 0]), np.interp(t, gps.t, gps.en_m[:, 1])])
    n = dataset.config.noise
    cov = np.diag([n.gps_sigma_m**2, n.gps_sigma_m**2, np.deg2rad(n.ahrs_sigma_deg) ** 2])
    return Trajectory(t, np.column_stack([xy, psi]), np.broadcast_to(cov, (t.size, 3, 3)).copy())


#: Pose sources by name (``--poses``; ``dr`` and ``gps`` are also ``--backend`` baselines).
#: The dataset settings dead reckoning does not use (the closed loops' models alone): it takes
#: the AHRS heading itself, so nothing turns it between samples and no bias walks or scales;
#: it has no lines. ``info`` and a ``dr`` run's ``config_used.toml`` name them as ignored.
DR_IGNORES = (
    "[motion] yaw_rate_source",
    "[noise] ahrs_bias_walk_deg_per_sqrt_s",
    "[noise] dvl_scale_sigma",
    "[noise] line_sigma_rho_m",
    "[noise] line_sigma_theta_deg",
)

#: The dataset settings the closed loops (EKF, iSAM2) take for their start pose only: their
#: AHRS model is ``[noise] ahrs_white_sigma_deg`` plus a bias of ``ahrs_bias_sigma_deg``.
#: ``info`` and a closed loop's ``config_used.toml`` say so.
CLOSED_LOOP_START_ONLY = ("[noise] ahrs_sigma_deg",)

POSE_SOURCES: dict[str, Callable[[Dataset], Trajectory]] = {
    "gps": gps_ahrs_trajectory,
    "dr": dead_reckoning_trajectory,
    "truth": truth_trajectory,
}


def pose_source_by_name(dataset: Dataset, name: str) -> Trajectory:
    """One of :data:`POSE_SOURCES` built on ``dataset``."""
    if name not in POSE_SOURCES:
        raise ValueError(f"--poses must be one of {sorted(POSE_SOURCES)}, got {name!r}")
    return POSE_SOURCES[name](dataset)
