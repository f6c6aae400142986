"""A dataset's start pose, motion noise and the pose sources that need no estimator.

GPS + AHRS (``gps``), dead reckoning (``dr``) and the simulator's truth (``truth``) all return a
:class:`sonarslam.slam.io.trajectory.Trajectory`, which implements the front end's
:class:`sonarslam.features.pose_source.PoseSource` (:data:`POSE_SOURCES`, :func:`pose_source_by_name`).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from sonarslam.datasets.records import GpsSeries
from sonarslam.datasets.source import Dataset
from sonarslam.features.geometry import FloatArray
from sonarslam.slam.eval.truth import truth_trajectory
from sonarslam.slam.io.trajectory import Trajectory
from sonarslam.slam.model.motion import body_yaw, dead_reckoning
from sonarslam.slam.model.noise import MotionNoise, dvl_scatter

__all__ = [
    "motion_noise",
    "start_pose",
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
    """
    noise = motion_noise(dataset)
    dvl = dataset.dvl
    t, v = dvl.t[dvl.valid], dvl.v_mps[dvl.valid]
    out = {f"dvl_scatter_p{p}_mps": float("nan") for p in (10, 50, 90, 99)}
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


def _require_gps(dataset: Dataset) -> GpsSeries:
    if dataset.gps is None:
        raise ValueError(f"{dataset.root}: no *_DGPS.log, so no start pose nor ground truth")
    return dataset.gps


def start_pose(dataset: Dataset) -> tuple[float, FloatArray, FloatArray]:
    """Start time, pose and covariance of every estimator (the ATE protocol).

    The start is the first GPS fix inside the navigation span; its position is that fix, its
    yaw the heading sensor's (through the AHRS mounting).
    """
    gps = _require_gps(dataset)
    t_nav0, t_nav1 = dataset.nav_span_s
    inside = np.flatnonzero((gps.t >= t_nav0) & (gps.t <= t_nav1))
    if inside.size == 0:
        raise ValueError(f"{dataset.root}: no GPS fix inside the navigation span")
    i = int(inside[0])
    t0 = float(gps.t[i])
    yaw_a = np.interp(t0, dataset.attitude.t, np.unwrap(dataset.attitude.yaw_rad))
    psi = float(body_yaw(yaw_a, dataset.config.ahrs_mounting, dataset.config.ahrs_deviation_rad))
    sigma_gps = dataset.config.noise.gps_sigma_m
    sigma_yaw = np.deg2rad(dataset.config.noise.ahrs_sigma_deg)
    cov = np.diag([sigma_gps**2, sigma_gps**2, sigma_yaw**2])
    return t0, np.array([gps.en_m[i, 0], gps.en_m[i, 1], psi]), cov


def dead_reckoning_trajectory(dataset: Dataset) -> Trajectory:
    """Dead reckoning of a ``dataset`` (DVL velocities rotated by the AHRS heading) over its
    navigation span, from the ATE protocol's start pose (the first GPS fix with the AHRS
    heading): body poses ``wTb`` ``(x_m, y_m, yaw_rad)`` in the readers' local East-North frame
    with their covariances, a :class:`sonarslam.features.pose_source.PoseSource`."""
    t0, pose0, cov0 = start_pose(dataset)
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
