"""The closed loop: back end -> poses -> front end -> lines -> back end (the design card's shape).

The driver walks the merged record stream in time order. Every record first moves the back end
to its time by one motion step (:func:`sonarslam.slam.model.motion.motion_step`: the DVL velocity held
since its sample, causal, its noise growing through a DVL gap, made the body velocity with its
lever arm compensated at the step's yaw rate (:func:`sonarslam.slam.model.motion.body_velocity`);
the yaw rate of the gyro or of the AHRS heading's own change, none through an AHRS gap, where
the DVL records carry the trajectory on). AHRS records update the heading; sonar beams go to the :class:`sonarslam.features.extractor.LineExtractor`,
whose only view of the vehicle is the :class:`sonarslam.features.pose_source.PoseSource` the back end
gives (:meth:`sonarslam.slam.backends.base.Backend.pose_source`); the lines it returns update the back end.
With ``"scans"`` among the back end's ``constraints`` the beams also go to the scan matcher
(:class:`sonarslam.features.scans.ScanMatcher`, the same seam), and each scan it completes goes to the
back end (:class:`sonarslam.slam.backends.base.ScanBackend`) with the matcher, which registers the pairs
the back end asks for; without ``"lines"`` the line extractor does not run.
GPS records are never used here (evaluation only).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
from tqdm import tqdm

from sonarslam.datasets.records import Attitude, DvlVelocity, GpsFix
from sonarslam.datasets.source import Dataset
from sonarslam.features.config import ExtractorConfig
from sonarslam.features.extractor import LineExtractor
from sonarslam.features.geometry import FloatArray, wrap_angle
from sonarslam.features.line import LineFeature
from sonarslam.features.scans import ScanConfig, ScanMatcher
from sonarslam.slam.backends.base import AnchoredOdometry, Backend, ScanBackend
from sonarslam.slam.io.trajectory import Trajectory
from sonarslam.slam.model.motion import body_velocity, body_yaw, motion_step, velocity_input
from sonarslam.slam.run.sources import motion_noise, start_pose
from sonarslam.sonar.beam import SonarBeam

__all__ = ["ClosedLoopResult", "run_closed_loop"]


@dataclass
class ClosedLoopResult:
    """What a closed loop estimated and measured.

    Attributes
    ----------
    trajectory : Trajectory
        The causal (filtered) pose at the start and at every AHRS record (and at every DVL
        record inside an AHRS gap), with covariances.
    backend : Backend
        The back end at the end of the run (its map, smoothed trajectory, graph...).
    features : list of LineFeature
        Every line the front end gave, in order.
    feature_landmarks : list of int or None
        The landmark each was associated with.
    wall_s, extractor_s, backend_s : float
        Time of the whole loop, of the extractor, of the back end (s).
    scan_matcher_s : float
        Time of the scan matcher building scans (s); its registrations are the back end's.
    counts : dict
        Records by kind (``beams``, ``ahrs``, ``dvl``).
    feature_seeds : list of int or None
        The landmark each feature seeded as a tentative line before the landmark existed.
    """

    trajectory: Trajectory
    backend: Backend
    features: list[LineFeature]
    feature_landmarks: list[int | None]
    wall_s: float
    extractor_s: float
    backend_s: float
    counts: dict[str, int] = field(default_factory=dict)
    feature_seeds: list[int | None] = field(default_factory=list)
    scan_matcher_s: float = 0.0


def run_closed_loop(
    dataset: Dataset,
    make_backend: Callable[[float, FloatArray, FloatArray], Backend],
    extractor_config: ExtractorConfig,
    progress: bool = True,
    t_end_s: float | None = None,
    label: str = "closed loop",
    scan_config: ScanConfig | None = None,
) -> ClosedLoopResult:
    """Run a back end in closed loop with the line extractor over a dataset.

    Parameters
    ----------
    dataset : Dataset
    make_backend : callable
        ``(t0_s, wTb0, P0) -> Backend`` at the start pose of the ATE protocol
        (:func:`sonarslam.slam.run.sources.start_pose`).
    extractor_config : ExtractorConfig
    progress : bool
        A progress bar over the records, named ``label``.
    t_end_s : float, optional
        Stop early (for tests and sweeps).
    scan_config : ScanConfig, optional
        The scan matcher's settings when the back end takes scans (default: its defaults).
    """
    wall0 = time.perf_counter()
    t0, pose0, cov0 = start_pose(dataset)
    t1 = dataset.nav_span_s[1] if t_end_s is None else min(t_end_s, dataset.nav_span_s[1])
    records = [r for r in dataset.stream(t0, t1) if not isinstance(r, GpsFix)]
    times = np.array([r.t for r in records])
    cfg = dataset.config
    noise = motion_noise(dataset)
    vin = velocity_input(times, dataset.dvl, cfg.dvl_mounting, noise)
    backend = make_backend(t0, pose0, cov0)
    odometry = AnchoredOdometry(t0, pose0)
    source = backend.pose_source(odometry)
    kinds = backend.config.constraint_kinds
    extractor = LineExtractor(extractor_config, cfg.sonar, cfg.sonar_mounting, source)
    matcher: ScanMatcher | None = None
    if "scans" in kinds:
        if not isinstance(backend, ScanBackend):
            raise ValueError(f"{type(backend).__name__} does not take scan constraints")
        matcher = ScanMatcher(scan_config or ScanConfig(), cfg.sonar, cfg.sonar_mounting, source)
    lines = "lines" in kinds

    traj_t: list[float] = [t0]
    traj_p: list[FloatArray] = [backend.pose]
    traj_c: list[FloatArray] = [backend.pose_cov]
    features: list[LineFeature] = []
    landmark_ids: list[int | None] = []
    yaw_rate = 0.0
    heading_rate = cfg.yaw_rate_source == "heading"
    prev_yaw: tuple[float, float] | None = None  # (t, body yaw) of the previous AHRS sample
    mount = cfg.dvl_mounting
    lever = (mount.x_m, mount.y_m)
    has_lever = lever != (0.0, 0.0)  # its compensation needs the step's own yaw rate
    v_prev, s_prev = np.zeros(2), float(vin.sigma_mps[0]) if len(records) else 0.0
    v_prev_dvl = np.zeros(2)
    t_prev, held_from = t0, t0  # previous record; since when its velocity sample is held
    t_ahrs = t0  # the newest AHRS sample (an AHRS gap: older than noise.ahrs_stale_s)
    extractor_s = backend_s = scan_matcher_s = 0.0
    counts = {"beams": 0, "ahrs": 0, "dvl": 0}
    for k, rec in enumerate(
        tqdm(records, disable=not progress, unit="rec", desc=label, mininterval=1.0)
    ):
        tb = time.perf_counter()
        # an AHRS gap: no turn, and the heading's variance grows with the gap
        fresh = t_prev - t_ahrs <= noise.ahrs_stale_s
        rate = yaw_rate if fresh else 0.0
        var_gap = noise.ahrs_gap_variance(t_prev, rec.t, t_ahrs)
        gyro = fresh and not heading_rate  # the back end's gyro bias enters this step
        if has_lever:  # the body velocity with the lever arm at the rate this step turns by
            v_b = body_velocity(v_prev_dvl, mount, rate)[0]
            step = motion_step(
                t_prev, rec.t, v_b, s_prev, rate, held_from, var_gap, gyro, lever_arm_m=lever
            )
        else:
            step = motion_step(t_prev, rec.t, v_prev, s_prev, rate, held_from, var_gap, gyro)
        odometry.append(rec.t, backend.predict(step), step.var_xy_m2)
        v_prev, s_prev = vin.v_b_mps[k], float(vin.sigma_mps[k])
        v_prev_dvl = vin.v_dvl_mps[k]
        t_prev, held_from = rec.t, max(float(vin.sample_t_s[k]), t0)
        if isinstance(rec, Attitude):
            counts["ahrs"] += 1
            yaw_b = float(body_yaw(rec.yaw_rad, cfg.ahrs_mounting, cfg.ahrs_deviation_rad))
            if heading_rate:  # the heading's change since its previous sample (causal)
                if prev_yaw is not None and rec.t > prev_yaw[0]:
                    yaw_rate = float(wrap_angle(yaw_b - prev_yaw[1])) / (rec.t - prev_yaw[0])
                prev_yaw = (rec.t, yaw_b)
            else:
                yaw_rate = rec.yaw_rate_rad_per_s
            backend.update_heading(rec.t, yaw_b)
            t_ahrs = rec.t
            traj_t.append(rec.t)
            traj_p.append(backend.pose)
            traj_c.append(backend.pose_cov)
            backend_s += time.perf_counter() - tb
        elif isinstance(rec, DvlVelocity):
            counts["dvl"] += 1
            if rec.t - t_ahrs > noise.ahrs_stale_s:  # an AHRS gap: the poses go on
                traj_t.append(rec.t)
                traj_p.append(backend.pose)
                traj_c.append(backend.pose_cov)
            backend_s += time.perf_counter() - tb
        elif isinstance(rec, SonarBeam):
            counts["beams"] += 1
            odometry.set_anchor(rec.t, backend.pose, backend.pose_cov)
            backend_s += time.perf_counter() - tb
            te = time.perf_counter()
            found = extractor.add(rec) if lines else []
            extractor_s += time.perf_counter() - te
            te = time.perf_counter()
            scan = matcher.add(rec) if matcher is not None else None
            scan_matcher_s += time.perf_counter() - te
            if scan is not None:
                assert matcher is not None and isinstance(backend, ScanBackend)
                tb = time.perf_counter()
                backend.update_scan(scan, matcher)
                backend_s += time.perf_counter() - tb
            if found:
                tb = time.perf_counter()
                ids = backend.update_lines(found)
                backend_s += time.perf_counter() - tb
                features.extend(found)
                landmark_ids.extend(ids)
    trajectory = Trajectory(np.asarray(traj_t), np.asarray(traj_p), np.asarray(traj_c))
    # associations a back end revised after their vote (a re-test when a loop closed)
    revised: dict[int, int | None] = getattr(backend, "revised_ids", {})
    landmark_ids = [revised.get(id(f), lm) for f, lm in zip(features, landmark_ids, strict=True)]
    seeded = {id(f): lm for f, lm in backend.map.seed_log}
    return ClosedLoopResult(
        trajectory=trajectory,
        backend=backend,
        features=features,
        feature_landmarks=landmark_ids,
        wall_s=time.perf_counter() - wall0,
        extractor_s=extractor_s,
        backend_s=backend_s,
        counts=counts,
        feature_seeds=[seeded.get(id(f)) for f in features],
        scan_matcher_s=scan_matcher_s,
    )
