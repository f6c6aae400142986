"""The closed loop: back end -> poses -> front end -> lines -> back end (the design card's shape).

The driver walks the merged record stream in time order. Every record first predicts the back
end to its time with the motion model's input (:func:`slam.model.motion.velocity_input`, causal).
AHRS records update the heading; sonar beams go to the :class:`features.extractor.LineExtractor`,
whose only view of the vehicle is a :class:`features.pose_source.PoseSource` provided by the back
end; the lines it returns update the back end. GPS records are never used here (evaluation only).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, Protocol

import numpy as np
import numpy.typing as npt
from tqdm import tqdm

from datasets.records import Attitude, DvlVelocity, GpsFix
from datasets.source import Dataset
from features.extractor import ExtractorConfig, LineExtractor
from features.geometry import FloatArray, between, compose, wrap_angle
from features.line import LineFeature
from features.pose_source import PoseSource
from slam.io.trajectory import Trajectory
from slam.model.motion import body_yaw, held_velocity_variance_step, velocity_input
from slam.run.sources import motion_noise, start_pose
from sonar.beam import SonarBeam

__all__ = ["AnchoredOdometry", "Backend", "ClosedLoopResult", "run_closed_loop"]


class AnchoredOdometry:
    """PoseSource of a filter: past poses from the odometry chain, anchored at the current estimate.

    ``wTb(t) = wTb_now * inverse(O(t_now)) * O(t)``, where ``O`` chains the relative motions of the
    filter's predictions. After a correction the whole stored sector moves rigidly with the
    current estimate, so the motion-distortion correction uses the (locally accurate) odometry
    and the absolute pose comes from the filter.

    :meth:`covariance` is the chain's own position variance accumulated from the DVL noise
    (isotropic, so frame-free) on top of the anchor's covariance: the extractor takes only its
    differences between beams (``ExtractorConfig.pose_uncertainty``), which are the odometry's
    uncertainty over the sector and so grow when the DVL degrades.

    The chain lives in growing buffers (amortised doubling) with its yaw kept unwrapped, and a
    query interpolates only over the samples spanning the queried times (a sector of beams), so
    a vote costs the same at the end of a long run as at its start.
    """

    def __init__(self, t0_s: float, wTb0: FloatArray, capacity: int = 4096) -> None:
        self._t = np.empty(capacity)
        self._odo = np.empty((capacity, 3))  # x, y, unwrapped yaw of O(t)
        self._var = np.empty(capacity)  # accumulated position variance of O(t), per axis (m^2)
        self._t[0] = t0_s
        self._odo[0] = 0.0
        self._var[0] = 0.0
        self._n = 1
        self._anchor_t = t0_s
        self._anchor = np.asarray(wTb0, dtype=np.float64).copy()
        self._anchor_cov: FloatArray | None = None

    def append(self, t_s: float, bTb_next: FloatArray, var_step_m2: float = 0.0) -> None:
        """Chain one step of relative motion ending at ``t_s``, whose position variance per
        axis is ``var_step_m2``."""
        if self._n == self._t.size:
            self._t = np.concatenate([self._t, np.empty(self._t.size)])
            self._odo = np.concatenate([self._odo, np.empty_like(self._odo)])
            self._var = np.concatenate([self._var, np.empty_like(self._var)])
        last = self._odo[self._n - 1]
        nxt = compose(last, bTb_next)
        nxt[2] = last[2] + bTb_next[2]  # keep the chain's yaw unwrapped
        self._t[self._n] = t_s
        self._odo[self._n] = nxt
        self._var[self._n] = self._var[self._n - 1] + var_step_m2
        self._n += 1

    def set_anchor(self, t_s: float, wTb: FloatArray, cov: FloatArray | None = None) -> None:
        self._anchor_t = t_s
        self._anchor = np.asarray(wTb, dtype=np.float64).copy()
        self._anchor_cov = cov

    def _chain_at(self, t_s: FloatArray) -> FloatArray:
        t, odo = self._t[: self._n], self._odo[: self._n]
        lo = max(int(np.searchsorted(t, t_s.min(), side="right")) - 1, 0)
        hi = min(int(np.searchsorted(t, t_s.max(), side="left")) + 1, self._n)
        t, odo = t[lo:hi], odo[lo:hi]
        return np.column_stack([np.interp(t_s, t, odo[:, k]) for k in range(3)])

    def poses(self, t_s: npt.ArrayLike) -> FloatArray:
        tq = np.atleast_1d(np.asarray(t_s, dtype=np.float64))
        chain = self._chain_at(np.append(tq, self._anchor_t))
        o_t, o_now = chain[:-1], chain[-1]
        return compose(compose(self._anchor, between(o_now, np.zeros(3))), o_t)

    def covariance(self, t_s: float) -> FloatArray | None:
        if self._anchor_cov is None:
            return None
        v = float(np.interp(t_s, self._t[: self._n], self._var[: self._n]))
        return np.asarray(self._anchor_cov) + np.diag([v, v, 0.0])


class Backend(Protocol):
    """What the driver needs from a SLAM back end."""

    @property
    def pose(self) -> FloatArray: ...

    @property
    def pose_cov(self) -> FloatArray: ...

    def predict(
        self, t_s: float, v_b_mps: FloatArray, sigma_v_mps: float, yaw_rate_radps: float
    ) -> FloatArray: ...

    def update_heading(self, t_s: float, yaw_body_rad: float) -> bool: ...

    def update_lines(self, features: list[LineFeature]) -> list[int | None]: ...

    seed_log: list[tuple[LineFeature, int]]  # (tentative observation, landmark it seeded)


@dataclass
class ClosedLoopResult:
    trajectory: Trajectory
    backend: Any
    features: list[LineFeature]
    feature_landmarks: list[int | None]  # landmark each feature was associated with, or None
    wall_s: float
    extractor_s: float
    backend_s: float
    counts: dict[str, int] = field(default_factory=dict)
    # landmark each feature seeded as a tentative line before the landmark existed, or None
    feature_seeds: list[int | None] = field(default_factory=list)


def run_closed_loop(
    dataset: Dataset,
    make_backend: Callable[[float, FloatArray, FloatArray], Any],
    extractor_config: ExtractorConfig,
    pose_source_of: Callable[[Any, AnchoredOdometry], PoseSource] | None = None,
    progress: bool = True,
    t_end_s: float | None = None,
) -> ClosedLoopResult:
    """Run a back end in closed loop with the line extractor over a dataset.

    Parameters
    ----------
    dataset : Dataset
    make_backend : callable
        ``(t0_s, wTb0, P0) -> backend`` (see :class:`Backend`).
    extractor_config : ExtractorConfig
    pose_source_of : callable, optional
        ``(backend, odometry) -> PoseSource`` given to the extractor; default the anchored
        odometry (filters). The factor graph gives its smoothed trajectory here.
    progress : bool
        A progress bar over the records.
    t_end_s : float, optional
        Stop early (for tests and sweeps).
    """
    wall0 = time.perf_counter()
    t0, pose0, cov0 = start_pose(dataset)
    t1 = dataset.nav_span_s[1] if t_end_s is None else min(t_end_s, dataset.nav_span_s[1])
    records = [r for r in dataset.stream(t0, t1) if not isinstance(r, GpsFix)]
    times = np.array([r.t for r in records])
    cfg = dataset.config
    vin = velocity_input(times, dataset.dvl, cfg.dvl_mounting, motion_noise(dataset))
    backend = make_backend(t0, pose0, cov0)
    odometry = AnchoredOdometry(t0, pose0)
    pose_source = pose_source_of(backend, odometry) if pose_source_of else odometry
    extractor = LineExtractor(extractor_config, cfg.sonar, cfg.sonar_mounting, pose_source)

    traj_t: list[float] = [t0]
    traj_p: list[FloatArray] = [backend.pose]
    traj_c: list[FloatArray] = [backend.pose_cov]
    features: list[LineFeature] = []
    landmark_ids: list[int | None] = []
    yaw_rate = 0.0
    heading_rate = cfg.yaw_rate_source == "heading"
    prev_yaw: tuple[float, float] | None = None  # (t, body yaw) of the previous AHRS sample
    v_prev, s_prev = np.zeros(2), float(vin.sigma_mps[0]) if len(records) else 0.0
    t_prev, held_from = t0, t0  # previous record; time of the DVL sample held since
    extractor_s = backend_s = 0.0
    counts = {"beams": 0, "ahrs": 0, "dvl": 0}
    for k, rec in enumerate(
        tqdm(records, disable=not progress, unit="rec", desc="closed loop", mininterval=1.0)
    ):
        tb = time.perf_counter()
        rel = backend.predict(rec.t, v_prev, s_prev, yaw_rate)
        dt = max(rec.t - t_prev, 0.0)
        odometry.append(
            rec.t, rel, float(held_velocity_variance_step(max(rec.t - held_from, dt), dt, s_prev))
        )
        v_prev, s_prev = vin.v_b_mps[k], float(vin.sigma_mps[k])
        t_prev, held_from = rec.t, float(vin.sample_t_s[k])
        if isinstance(rec, Attitude):
            counts["ahrs"] += 1
            yaw_b = float(body_yaw(rec.yaw_rad, cfg.ahrs_mounting, cfg.ahrs_deviation_rad))
            if heading_rate:  # the heading's change since its previous sample (causal)
                if prev_yaw is not None and rec.t > prev_yaw[0]:
                    yaw_rate = float(wrap_angle(yaw_b - prev_yaw[1])) / (rec.t - prev_yaw[0])
                prev_yaw = (rec.t, yaw_b)
            else:
                yaw_rate = rec.yaw_rate_radps
            backend.update_heading(rec.t, yaw_b)
            traj_t.append(rec.t)
            traj_p.append(backend.pose)
            traj_c.append(backend.pose_cov)
            backend_s += time.perf_counter() - tb
        elif isinstance(rec, DvlVelocity):
            counts["dvl"] += 1
            backend_s += time.perf_counter() - tb
        elif isinstance(rec, SonarBeam):
            counts["beams"] += 1
            odometry.set_anchor(rec.t, backend.pose, backend.pose_cov)
            backend_s += time.perf_counter() - tb
            te = time.perf_counter()
            found = extractor.add(rec)
            extractor_s += time.perf_counter() - te
            if found:
                tb = time.perf_counter()
                ids = backend.update_lines(found)
                backend_s += time.perf_counter() - tb
                features.extend(found)
                landmark_ids.extend(ids)
    trajectory = Trajectory(np.asarray(traj_t), np.asarray(traj_p), np.asarray(traj_c))
    seeded = {id(f): lm for f, lm in backend.seed_log}
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
    )
