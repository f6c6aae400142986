"""EKF-SLAM with line landmarks on filterpy's ExtendedKalmanFilter.

State ``x = [x, y, psi, b, delta, rho_1, theta_1, ..., rho_L, theta_L]``:

* ``x, y, psi``: the body pose ``wTb`` (m, m, rad);
* ``b``: the AHRS heading bias (rad), a constant with prior ``ahrs_bias_sigma_deg``: the AHRS
  measures ``psi + b``. Modelled so that the filter never believes its heading better than the
  compass can tell it (a white-noise model at 1 Hz would, and would be inconsistent);
* ``delta``: the misalignment of the DVL velocity with the body heading (rad), a constant with
  prior ``misalignment_sigma_deg``: the vehicle moves along ``R(psi + delta) v_b``. Line landmarks
  make it observable; it absorbs the error of the GPS-free DVL/AHRS calibration;
* world lines ``(rho_w, theta_w)`` (:mod:`features.geometry` conventions).

Prediction uses :func:`slam.model.motion.propagate` on the pose block only (the landmarks are static,
so only the pose rows and columns of P change). Updates are filterpy's (Joseph form) with H
evaluated at the predicted state: the AHRS heading, and each line observation in the sonar frame
R, ``z = line_world_to_frame(L, wTb * bTs)`` (design.md conventions), Jacobians from
:mod:`features.geometry` (checked numerically in the tests).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
from filterpy.kalman import ExtendedKalmanFilter
from scipy.stats import chi2

from features.geometry import (
    FloatArray,
    along_line,
    between,
    compose,
    compose_jacobians,
    line_frame_to_world,
    line_world_to_frame,
    transform_points,
    wrap_angle,
)
from features.line import LineFeature
from slam.mapping.association import (
    FLIP_RHO,
    AssociationConfig,
    AssociationProblem,
    associate,
    extent_allowed,
    line_innovation,
)
from slam.mapping.landmarks import landmark_record
from slam.model.motion import held_velocity_variance_step
from sonar.beam import Mounting

__all__ = ["EkfConfig", "Landmark", "LineEkf", "POSE", "N_VEHICLE"]

POSE = slice(0, 3)
N_VEHICLE = 5  # x, y, psi, b, delta


@dataclass(frozen=True)
class EkfConfig:
    """Settings of the EKF and its landmark management.

    Attributes
    ----------
    association : AssociationConfig
    ahrs_white_sigma_deg : float
        White noise of one AHRS heading (deg).
    ahrs_bias_sigma_deg : float
        Prior 1-sigma of the constant AHRS bias (deg).
    ahrs_period_s : float
        Time between AHRS updates used (s); the AHRS logs at 10 Hz, its errors are not white.
    gyro_sigma_radps : float
        Heading process noise, as a yaw-rate noise (rad/s).
    estimate_misalignment : bool
        Estimate ``delta``; when False it is held at 0 with zero variance. Off by default: on a
        simulated harbour with a 5 deg DVL mounting error it recovers -4.83 deg; on the real
        marina it moves the ATE by under 2 m either way and is not well determined (the thick
        echo bands bias the lines by about as much as a few degrees of misalignment would).
    misalignment_sigma_deg : float
        Prior 1-sigma of ``delta`` (deg).
    tentative_observations : int
        A new line becomes a landmark when seen this many times, each compatible with the
        first (chi2 gate of ``association.gate_probability`` in the world frame) ...
    tentative_max_age_s : float
        ... within this time (s); older tentative lines are dropped.
    min_rho_m : float
        Observations of lines closer than this to the sonar are not used (sign ambiguity,
        the sonar's near field).
    extent_margin_m : float or None
        A landmark is paired only with observations whose world segment reaches its extent
        within this margin (m), :func:`slam.mapping.association.extent_allowed`; None: no extent gate.
        10 m: on the marina it keeps a landmark from spanning the gap to a collinear wall of the
        other basin (extents of 200-490 m without it) and takes the ATE down by ~1 m; on the
        simulated harbours precision and recall do not move.
    first_estimates_jacobians : bool
        FEJ-EKF: line Jacobians at the landmarks' first estimates (consistency; see
        :meth:`LineEkf._predict_line`).
    """

    association: AssociationConfig = field(default_factory=AssociationConfig)
    ahrs_white_sigma_deg: float = 1.0
    ahrs_bias_sigma_deg: float = 2.0
    ahrs_period_s: float = 1.0
    gyro_sigma_radps: float = 0.005
    estimate_misalignment: bool = False
    misalignment_sigma_deg: float = 5.0
    tentative_observations: int = 2
    tentative_max_age_s: float = 60.0
    min_rho_m: float = 1.0
    extent_margin_m: float | None = 10.0
    first_estimates_jacobians: bool = True


@dataclass
class Landmark:
    """A line landmark: its state index, extent along the line (m) and observation count."""

    id: int
    index: int
    n_obs: int
    s_min_m: float
    s_max_m: float
    first_line_w: FloatArray = field(default_factory=lambda: np.zeros(2))


@dataclass(eq=False)
class _Tentative:
    t: float
    line_w: FloatArray
    cov_w: FloatArray
    ends_w: FloatArray  # (2n, 2) world end points of its observations (m)
    features: list[LineFeature] = field(default_factory=list)


class LineEkf:
    """EKF-SLAM with line landmarks; see the module docstring for the state.

    Parameters
    ----------
    t0_s : float
        Start time (Unix s).
    wTb0 : ndarray, shape (3,)
        Start pose.
    P0 : ndarray, shape (3, 3)
        Start pose covariance.
    sonar_mounting : Mounting
        ``bTs`` of the sonar head.
    config : EkfConfig
    """

    def __init__(
        self,
        t0_s: float,
        wTb0: FloatArray,
        P0: FloatArray,
        sonar_mounting: Mounting,
        config: EkfConfig,
    ) -> None:
        self.config = config
        self.bTs = sonar_mounting.as_pose()
        self.t_s = t0_s
        kf = ExtendedKalmanFilter(dim_x=N_VEHICLE, dim_z=2)
        kf.x = np.zeros(N_VEHICLE)
        kf.x[POSE] = wTb0
        P = np.zeros((N_VEHICLE, N_VEHICLE))
        P[POSE, POSE] = P0
        var_b = np.deg2rad(config.ahrs_bias_sigma_deg) ** 2
        # psi0 came from the AHRS, which measures psi + b: psi and b are anti-correlated.
        P[2, 2] += var_b
        P[3, 3] = var_b
        P[2, 3] = P[3, 2] = -var_b
        P[4, 4] = (
            np.deg2rad(config.misalignment_sigma_deg) ** 2 if config.estimate_misalignment else 0.0
        )
        kf.P = P
        self.kf = kf
        self.landmarks: list[Landmark] = []
        self._tentative: list[_Tentative] = []
        self._next_id = 0
        self._last_ahrs_t = -np.inf
        self._held_v: tuple[float, float] | None = None
        self._held_s = 0.0
        self.stats = {
            "observations": 0,
            "associated": 0,
            "new_landmarks": 0,
            "tentative_dropped": 0,
            "rejected_near": 0,
            "ahrs_updates": 0,
        }
        self.association_log: list[
            tuple[float, int, int | None]
        ] = []  # (t, obs index, landmark id)
        # tentative observations of a line that became a landmark, with its id: they seeded it
        # (the EKF initialises from the promoting observation; these were not updates)
        self.seed_log: list[tuple[LineFeature, int]] = []

    # -- state access ----------------------------------------------------------------------

    @property
    def x(self) -> FloatArray:
        return np.asarray(self.kf.x)

    @property
    def P(self) -> FloatArray:
        return np.asarray(self.kf.P)

    @property
    def pose(self) -> FloatArray:
        return self.x[POSE].copy()

    @property
    def pose_cov(self) -> FloatArray:
        return self.P[POSE, POSE].copy()

    def landmark_line(self, lm: Landmark) -> FloatArray:
        return self.x[lm.index : lm.index + 2].copy()

    # -- prediction ------------------------------------------------------------------------

    def predict(
        self, t_s: float, v_b_mps: FloatArray, sigma_v_mps: float, yaw_rate_radps: float
    ) -> FloatArray:
        """Propagate to ``t_s`` with body velocity and yaw rate held since the last step.

        Returns the relative motion ``bTb'`` of this step (the odometry the front end chains).
        """
        dt = t_s - self.t_s
        if dt <= 0.0:
            return np.zeros(3)
        x, P = self.kf.x, self.kf.P
        before = x[POSE].copy()
        a = x[2] + x[4]
        c, s = np.cos(a), np.sin(a)
        dx = dt * (c * v_b_mps[0] - s * v_b_mps[1])
        dy = dt * (s * v_b_mps[0] + c * v_b_mps[1])
        x[0] += dx
        x[1] += dy
        x[2] = wrap_angle(x[2] + dt * yaw_rate_radps)
        F = np.eye(N_VEHICLE)
        F[0, 2] = -dy
        F[1, 2] = dx
        if self.config.estimate_misalignment:
            F[0, 4] = -dy
            F[1, 4] = dx
        # one held DVL sample has one error: count it per sample, not per step (slam.model.motion)
        v_key = (float(v_b_mps[0]), float(v_b_mps[1]))
        self._held_s = self._held_s + dt if v_key == self._held_v else dt
        self._held_v = v_key
        Q = np.zeros((N_VEHICLE, N_VEHICLE))
        Q[0, 0] = Q[1, 1] = float(held_velocity_variance_step(self._held_s, dt, sigma_v_mps))
        Q[2, 2] = (dt * self.config.gyro_sigma_radps) ** 2
        V = slice(0, N_VEHICLE)
        P[V, :] = F @ P[V, :]
        P[:, V] = P[:, V] @ F.T
        P[V, V] += Q
        self.t_s = t_s
        return between(before, x[POSE])

    # -- updates ---------------------------------------------------------------------------

    def _update(
        self, z: FloatArray, H: FloatArray, hx: FloatArray, R: FloatArray, residual
    ) -> None:  # noqa: ANN001
        n = self.kf.x.size
        self.kf.update(z, lambda _x: H, lambda _x: hx, R=R, residual=residual)
        self.kf.x[2] = wrap_angle(self.kf.x[2])
        for lm in self.landmarks:
            i = lm.index
            if self.kf.x[i] < 0.0:  # keep landmarks normalised; flip the state and its covariance
                J = np.eye(n)
                J[i, i] = -1.0
                self.kf.x[i] = -self.kf.x[i]
                self.kf.x[i + 1] += np.pi
                self.kf.P = J @ self.kf.P @ J.T
            self.kf.x[i + 1] = wrap_angle(self.kf.x[i + 1])

    def update_heading(self, t_s: float, yaw_body_rad: float) -> bool:
        """AHRS heading update (``z = psi + b``), at most every ``ahrs_period_s``."""
        if t_s - self._last_ahrs_t < self.config.ahrs_period_s:
            return False
        self._last_ahrs_t = t_s
        n = self.kf.x.size
        H = np.zeros((1, n))
        H[0, 2] = H[0, 3] = 1.0
        hx = np.array([self.kf.x[2] + self.kf.x[3]])
        R = np.array([[np.deg2rad(self.config.ahrs_white_sigma_deg) ** 2]])
        self.kf.dim_z = 1
        self._update(np.array([yaw_body_rad]), H, hx, R, lambda a, b: wrap_angle(a - b))
        self.kf.dim_z = 2
        self.stats["ahrs_updates"] += 1
        return True

    def _predict_line(
        self, lm: Landmark, pose_lin: FloatArray | None = None
    ) -> tuple[FloatArray, FloatArray]:
        """Predicted observation of a landmark in the sonar frame and its full Jacobian (2, n).

        With ``first_estimates_jacobians`` the Jacobian is evaluated at the landmark's first
        estimate and at ``pose_lin`` (the propagated pose of this batch), as the FEJ-EKF of
        Huang, Mourikis & Roumeliotis (2008): without it the filter gains spurious information
        on the unobservable global heading and becomes overconfident.
        """
        pose = self.x[POSE]
        wTs = compose(pose, self.bTs)
        z_hat, H_line, H_sensor = line_world_to_frame(self.landmark_line(lm), wTs)
        if self.config.first_estimates_jacobians:
            pose = pose if pose_lin is None else pose_lin
            wTs_lin = compose(pose, self.bTs)
            z_lin, H_line, H_sensor = line_world_to_frame(lm.first_line_w, wTs_lin)
            if line_innovation(z_lin, z_hat)[1]:  # same line seen from the other side of 0
                H_line, H_sensor = (
                    -H_line * np.array([[1.0], [-1.0]]),
                    -H_sensor * np.array([[1.0], [-1.0]]),
                )
        J_pose, _ = compose_jacobians(pose, self.bTs)
        H = np.zeros((2, self.x.size))
        H[:, POSE] = H_sensor @ J_pose
        H[:, lm.index : lm.index + 2] = H_line
        return z_hat, H

    def update_lines(self, features: list[LineFeature]) -> list[int | None]:
        """Associate the lines of one vote to landmarks (JCBB/NN), update, manage new ones.

        Returns the landmark id of each feature (None: not associated).
        """
        use = [f for f in features if f.rho_m >= self.config.min_rho_m]
        self.stats["rejected_near"] += len(features) - len(use)
        if not use:
            return [None] * len(features)
        self.stats["observations"] += len(use)
        z = np.array([f.z for f in use])
        R = np.array([f.cov for f in use])
        pose_lin = self.x[POSE].copy()
        preds = [self._predict_line(lm, pose_lin) for lm in self.landmarks]
        z_hat = np.array([p[0] for p in preds]).reshape(-1, 2)
        H = np.array([p[1] for p in preds]).reshape(-1, 2, self.x.size)
        allowed = None
        if self.config.extent_margin_m is not None and self.landmarks:
            wTs = compose(self.x[POSE], self.bTs)
            allowed = extent_allowed(
                np.array([self.landmark_line(lm) for lm in self.landmarks]),
                np.array([[lm.s_min_m, lm.s_max_m] for lm in self.landmarks]),
                np.array([transform_points(wTs, f.endpoints_r) for f in use]),
                self.config.extent_margin_m,
            )
        pairing = associate(
            AssociationProblem(z, R, z_hat, H, self.P, allowed), self.config.association
        )
        ids: dict[int, int | None] = {}
        # updates first (sequentially, re-linearised at the updated state), then new lines
        for i, j in enumerate(pairing):
            if j is None:
                continue
            lm = self.landmarks[j]
            z_hat_j, H_j = self._predict_line(lm, pose_lin)
            _, flipped = line_innovation(z[i], z_hat_j)
            R_i = FLIP_RHO @ R[i] @ FLIP_RHO if flipped else R[i]
            self._update(z[i], H_j, z_hat_j, R_i, lambda a, b: line_innovation(a, b)[0])
            lm.n_obs += 1
            self._grow_extent(lm, use[i])
            self.stats["associated"] += 1
            ids[i] = lm.id
        for i, j in enumerate(pairing):
            if j is None:
                ids[i] = self._new_line(use[i])
        for i in range(len(use)):
            self.association_log.append((use[i].t, i, ids[i]))
        by_feature = {id(f): ids[i] for i, f in enumerate(use)}
        return [by_feature.get(id(f)) for f in features]

    # -- landmarks -------------------------------------------------------------------------

    def _observation_in_world(
        self, f: LineFeature
    ) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
        pose = self.x[POSE]
        wTs = compose(pose, self.bTs)
        line_w, G_line, G_sensor = line_frame_to_world(f.z, wTs)
        J_pose, _ = compose_jacobians(pose, self.bTs)
        return line_w, G_line, G_sensor @ J_pose, wTs

    def _new_line(self, f: LineFeature) -> int | None:
        """A tentative line, promoted to a landmark when seen again (EkfConfig docs)."""
        line_w, G_z, G_pose, wTs = self._observation_in_world(f)
        P_pose = self.P[POSE, POSE]
        cov_w = G_pose @ P_pose @ G_pose.T + G_z @ f.cov @ G_z.T
        ends_w = transform_points(wTs, f.endpoints_r)
        cfg = self.config
        self._tentative = [c for c in self._tentative if f.t - c.t <= cfg.tentative_max_age_s]
        gate = chi2.ppf(cfg.association.gate_probability, 2)
        for cand in self._tentative:
            nu, _ = line_innovation(line_w, cand.line_w)
            if nu @ np.linalg.solve(cov_w + cand.cov_w, nu) <= gate:
                cand.ends_w = np.vstack([cand.ends_w, ends_w])
                if len(cand.features) + 1 >= cfg.tentative_observations:
                    self._tentative.remove(cand)
                    lm_id = self._augment(f, cand.ends_w)
                    self.seed_log.extend((g, lm_id) for g in cand.features)
                    return lm_id
                cand.features.append(f)
                return None
        if cfg.tentative_observations <= 1:
            return self._augment(f, ends_w)
        self._tentative.append(_Tentative(f.t, line_w, cov_w, ends_w, [f]))
        return None

    def _augment(self, f: LineFeature, ends_w: FloatArray) -> int:
        """Add a landmark from observation ``f`` with the full cross-covariances; its extent
        spans ``ends_w`` (world points of its observations) on its own line (the tentative
        lines may be in the other representation, whose along-line axis is reversed)."""
        line_w, G_z, G_pose, _ = self._observation_in_world(f)
        x, P = self.x, self.P
        n = x.size
        P_new = np.zeros((n + 2, n + 2))
        P_new[:n, :n] = P
        cross = G_pose @ P[POSE, :]  # (2, n)
        P_new[n:, :n] = cross
        P_new[:n, n:] = cross.T
        P_new[n:, n:] = G_pose @ P[POSE, POSE] @ G_pose.T + G_z @ f.cov @ G_z.T
        kf = self.kf
        kf.x = np.concatenate([x, line_w])
        kf.P = P_new
        kf.dim_x = n + 2
        kf._I = np.eye(n + 2)
        s = along_line(line_w, ends_w)
        lm = Landmark(self._next_id, n, 1, float(s.min()), float(s.max()), line_w.copy())
        self._next_id += 1
        self.landmarks.append(lm)
        self.stats["new_landmarks"] += 1
        return lm.id

    def _grow_extent(self, lm: Landmark, f: LineFeature) -> None:
        wTs = compose(self.x[POSE], self.bTs)
        ends_w = transform_points(wTs, f.endpoints_r)
        s = along_line(self.landmark_line(lm), ends_w)
        lm.s_min_m = min(lm.s_min_m, float(s.min()))
        lm.s_max_m = max(lm.s_max_m, float(s.max()))

    def map_json(self) -> list[dict[str, Any]]:
        """Per landmark: id, rho, theta, cov, world endpoints, observation count."""
        return [
            landmark_record(
                lm.id,
                self.landmark_line(lm),
                self.P[lm.index : lm.index + 2, lm.index : lm.index + 2],
                lm.s_min_m,
                lm.s_max_m,
                lm.n_obs,
            )
            for lm in self.landmarks
        ]
