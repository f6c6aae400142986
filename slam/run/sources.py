"""A dataset's start pose, motion noise and the pose sources that need no estimator.

GPS + AHRS (``gps``), dead reckoning (``dr``) and the simulator's truth (``truth``) all return a
:class:`sonarslam.slam.io.trajectory.Trajectory`, which implements the front end's
:class:`sonarslam.features.pose_source.PoseSource` (:data:`POSE_SOURCES`, :func:`pose_source_by_name`).
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Callable
from dataclasses import dataclass, replace

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
    "DVL_LEVER_ARM_TOLERANCE_M",
    "LeverArmFit",
    "dvl_lever_arm_from_turns",
    "warn_dvl_lever_arm",
    "dvl_body_velocities",
    "mounting_yaw_said",
    "DVL_SIGMA_OVER_SCATTER_MAX",
    "motion_noise",
    "start_pose",
    "start_pose_origin",
    "gps_ahrs_trajectory",
    "dead_reckoning_trajectory",
    "lateral_mirror_trajectory",
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


#: The DVL's position that its velocities imply (:func:`dvl_lever_arm_from_turns`) may lie this
#: far (m) from ``[mounting.dvl] x_m, y_m`` before :func:`warn_dvl_lever_arm` warns. Measured on
#: correct runs (docs/bad-input.md): the simulated worlds within 0.16 m, the marina within 0.26
#: m; a lever arm of 0.25 m written 2.5 is 2.25 m off.
DVL_LEVER_ARM_TOLERANCE_M = 1.0
#: ... and only when the fit's standard error is under a quarter of that (a run that hardly
#: turns cannot tell where its DVL is).
DVL_LEVER_ARM_MAX_SE_M = 0.25
#: The yaw rate of the fit is the body heading's change over +- this (s) about each DVL row: the
#: rate of one AHRS sample to the next is noise-dominated, and noise in the regressor shrinks
#: the fitted lever arm toward 0 (errors in variables).
DVL_LEVER_RATE_HALF_WINDOW_S = 1.0


@dataclass(frozen=True)
class LeverArmFit:
    """Where the DVL's velocities put it on the body (:func:`dvl_lever_arm_from_turns`).

    Attributes
    ----------
    x_m, y_m : float
        The DVL's position in the body frame that the turns imply (m, x forward, y left); NaN
        with too few rows.
    x_se_m, y_se_m : float
        Their standard errors (m).
    rows : int
        DVL rows fitted.
    yaw_rate_sd_rad_per_s : float
        The spread of the yaw rate over those rows (rad/s): what the fit has to go on.
    """

    x_m: float
    y_m: float
    x_se_m: float
    y_se_m: float
    rows: int
    yaw_rate_sd_rad_per_s: float

    @property
    def decisive(self) -> bool:
        """True when both standard errors are under :data:`DVL_LEVER_ARM_MAX_SE_M`."""
        return max(self.x_se_m, self.y_se_m) < DVL_LEVER_ARM_MAX_SE_M


def _slope_and_se(w: FloatArray, v: FloatArray) -> tuple[float, float]:
    """The slope of ``v = a + b w`` by least squares after one pass that drops residuals beyond
    four robust standard deviations (1.4826 MAD), and its standard error."""
    design = np.column_stack([np.ones_like(w), w])
    keep = np.ones(w.size, dtype=bool)
    for _ in range(2):
        coef = np.linalg.lstsq(design[keep], v[keep], rcond=None)[0]
        r = v - design @ coef
        mad = 1.4826 * float(np.median(np.abs(r[keep] - np.median(r[keep]))))
        keep = np.abs(r) <= 4.0 * max(mad, 1e-9)
    coef = np.linalg.lstsq(design[keep], v[keep], rcond=None)[0]
    r = v[keep] - design[keep] @ coef
    n = int(keep.sum())
    spread = float(np.sum((w[keep] - w[keep].mean()) ** 2))
    if n < 3 or spread <= 0.0:
        return math.nan, math.inf
    return float(coef[1]), math.sqrt(float(r @ r) / (n - 2) / spread)


def dvl_lever_arm_from_turns(dataset: Dataset) -> LeverArmFit:
    """Where on the body the DVL's velocities say it is, from the turns (GPS-free).

    A DVL at ``r = (x, y)`` measures its own point's velocity, the body origin's plus
    ``omega x r = omega (-y, x)`` (:func:`sonarslam.slam.model.motion.body_velocity`): across the
    vehicle ``v_y + omega x``, along it ``v_x - omega y``. The locked rows' velocities in body
    axes (the mounting's yaw, no lever arm taken off) are fitted against the yaw rate (the body
    heading's change over +- :data:`DVL_LEVER_RATE_HALF_WINDOW_S`) with an intercept: the slopes
    are ``x`` and ``-y``. The vehicle's own sway and surge are taken as uncorrelated with its
    yaw rate (a real vehicle's pivot point lies off its origin by tens of centimetres: the
    marina's fit is within 0.26 m of its configured lever arm). A lateral axis of the wrong
    sign reads as ``-x``.
    """
    dvl, att = dataset.dvl, dataset.attitude
    mounting = dataset.config.dvl_mounting
    t = dvl.t[dvl.valid]
    v = body_velocity(dvl.v_mps[dvl.valid], replace(mounting, x_m=0.0, y_m=0.0))
    h = DVL_LEVER_RATE_HALF_WINDOW_S
    inside = (t - h >= att.t[0]) & (t + h <= att.t[-1]) if att.t.size else t < -math.inf
    nothing = LeverArmFit(math.nan, math.nan, math.inf, math.inf, int(inside.sum()), math.nan)
    if inside.sum() < 50:
        return nothing
    psi = np.unwrap(
        body_yaw(att.yaw_rad, dataset.config.ahrs_mounting, dataset.config.ahrs_deviation_rad)
    )
    t, v = t[inside], v[inside]
    w = (np.interp(t + h, att.t, psi) - np.interp(t - h, att.t, psi)) / (2.0 * h)
    x, x_se = _slope_and_se(w, v[:, 1])
    minus_y, y_se = _slope_and_se(w, v[:, 0])
    return LeverArmFit(x, -minus_y, x_se, y_se, int(t.size), float(np.std(w)))


def warn_dvl_lever_arm(dataset: Dataset, fit: LeverArmFit | None = None) -> str:
    """Warn when the DVL's position that its turns imply (:func:`dvl_lever_arm_from_turns`,
    ``fit``, computed when not given) lies more than :data:`DVL_LEVER_ARM_TOLERANCE_M` from
    ``[mounting.dvl] x_m, y_m``: a lever arm in centimetres or decimetres taken as metres, or a
    DVL lateral axis of the wrong sign. The warning's text, or "" when it does not."""
    fit = fit if fit is not None else dvl_lever_arm_from_turns(dataset)
    m = dataset.config.dvl_mounting
    if not fit.decisive:
        return ""
    off = math.hypot(fit.x_m - m.x_m, fit.y_m - m.y_m)
    if not off > DVL_LEVER_ARM_TOLERANCE_M:
        return ""
    causes = [
        "a lever arm given in centimetres or decimetres for metres (x_m = 3.5 for 0.35 m)",
        "a position measured from another origin than the body's (the AHRS's, the GPS antenna's)",
    ]
    if math.hypot(fit.x_m + m.x_m, fit.y_m - m.y_m) < DVL_LEVER_ARM_TOLERANCE_M:
        causes.insert(
            0,
            "a DVL lateral axis of the wrong sign (x reads as minus x_m: the velocities' y, or"
            " the reader's frame, mirrored; no mounting yaw can undo it)",
        )
    message = (
        f"{dataset.root}: the DVL's velocities follow the yaw rate as a DVL at x {fit.x_m:+.2f}"
        f" ± {fit.x_se_m:.2f} m, y {fit.y_m:+.2f} ± {fit.y_se_m:.2f} m on the body would"
        f" ({fit.rows} rows), but [mounting.dvl] x_m = {m.x_m:g}, y_m = {m.y_m:g} ({m.source}),"
        f" {off:.1f} m away, more than the {DVL_LEVER_ARM_TOLERANCE_M:g} m a vehicle's own"
        f" sway explains: {'; or '.join(causes)}. Give [mounting.dvl] x_m, y_m in metres from"
        " the body origin; every estimate's turns carry the error"
    )
    warnings.warn(message, DataWarning, stacklevel=2)
    return message


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


def lateral_mirror_trajectory(dataset: Dataset) -> Trajectory:
    """Dead reckoning (:func:`dead_reckoning_trajectory`) with the DVL's velocity mirrored across
    the body's forward axis: its body-frame lateral component negated (the lever arm's turning
    term kept). Against the sonar it tells whether the DVL's lateral axis has the right sign
    (:func:`sonarslam.slam.eval.loops.lateral_gain`)."""
    a = dataset.config.dvl_mounting.yaw_rad
    # R(-a) diag(1, -1) R(a): a reflection of the DVL frame about the body's x axis
    c2, s2 = math.cos(2.0 * a), math.sin(2.0 * a)
    reflect = np.array([[c2, -s2], [-s2, -c2]])
    mirrored_dvl = replace(dataset.dvl, v_mps=dataset.dvl.v_mps @ reflect.T)
    return dead_reckoning_trajectory(replace(dataset, dvl=mirrored_dvl))


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
