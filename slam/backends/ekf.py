"""EKF-SLAM with line landmarks on filterpy's ExtendedKalmanFilter.

State ``x = [x, y, psi, b, delta, k, g, rho_1, theta_1, ..., rho_L, theta_L]``:

* ``x, y, psi``: the body pose ``wTb`` (m, m, rad);
* ``b``: the AHRS heading bias (rad) with prior ``ahrs_bias_sigma_deg``, constant or a random
  walk (``ahrs_bias_walk_deg_per_sqrt_s``): the AHRS measures ``psi + b`` (both of the
  dataset's ``[noise]``, :class:`sonarslam.datasets.config.NoiseConfig`);
* ``delta``: the misalignment of the DVL velocity with the body heading (rad), a constant with
  prior ``misalignment_sigma_deg`` when ``estimate_misalignment``, else held at 0;
* ``k``: the DVL's scale-factor error, a constant with prior ``[noise] dvl_scale_sigma`` (0: held
  at 0);
* ``g``: the gyro's yaw-rate bias (rad/s), a constant with prior ``gyro_bias_sigma_deg_per_s``:
  a step whose heading change integrates the gyro turns by ``dyaw - g dt``
  (:attr:`sonarslam.slam.model.motion.MotionStep.gyro_dt_s`), and with a DVL lever arm ``r``
  its displacement by ``g gyro_dt (-r_y, r_x)`` too (the lever-arm term ``-omega x r`` of the
  body velocity turns with the gyro's rate, :attr:`MotionStep.dx_dbias_m_s`; that term is rotated
  by ``delta`` and scaled by ``1 + k`` with the rest, a product of two small terms); the AHRS
  headings observe it. Left
  out, a gyro bias (docs/design-decisions.md) is taken for the AHRS bias's walk
  when the bias walks, and the heading spins away; with the AHRS heading's own change as the rate
  (``yaw_rate_source = "heading"``) no step involves it and it stays at its prior;
* only when estimated (``estimate_sonar_mount``, ``range_scale_sigma > 0``, both off by
  default, so that the state above is all there is), the sonar's calibration, constants after
  ``g`` (:meth:`LineEkf.calibration_index`): its mounting ``bTs`` ``(x, y, yaw)`` with the
  dataset's as prior mean and ``sonar_mount_sigma_m``, ``sonar_mount_sigma_deg`` as 1-sigma (with
  ``sonar_yaw_prior = "dead_reckoning"`` and the misalignment estimated, the prior on ``yaw -
  delta``), then its range scale ``s`` with prior 1 and ``range_scale_sigma``; every line is
  then predicted by :func:`sonarslam.slam.model.calibration.line_prediction_calibrated` and a new
  landmark put in the world by :func:`sonarslam.slam.model.calibration.world_line_calibrated`,
  at the current estimate of both. They belong to the vehicle block below;
* world lines ``(rho_w, theta_w)`` (:mod:`sonarslam.features.geometry` conventions), one per active
  landmark (:meth:`LineEkf.index`); kept normalised. A landmark merged into another (the landmark
  layer found them one wall) is tied to it by an exact update and leaves the state.

Prediction integrates the motion model (:mod:`sonarslam.slam.model.motion`) on the vehicle block only (the
landmarks are static, so only the vehicle rows and columns of P change). Between two updates the
steps are batched: each step propagates the vehicle block (7 x 7 without the calibration; the
driver reads the pose covariance at every record) and multiplies its Jacobian into their product
``Phi``; the vehicle-landmark block takes ``Phi`` once, when the full covariance is next needed
(:meth:`LineEkf._flush`), not 7 x n work per record. Updates are in the Joseph form with H
evaluated at the predicted state: the AHRS heading by :func:`scalar_joseph_update` (rank 1,
O(n^2), exactly symmetric), each line observation in the sonar frame R
(:func:`sonarslam.slam.model.lines.line_prediction`, or its calibrated form) by filterpy's, its
result symmetrised. Which observation
updates which landmark, and when a new line becomes one, is the landmark layer's
(:class:`sonarslam.slam.mapping.landmarks.LandmarkMap`); this class holds the filter state only.

A tentative line's gate compares two views of it with the joint covariance of the two poses
(:meth:`sonarslam.slam.mapping.landmarks.LandmarkMap.tentative_distance`). The filter keeps the
cross-covariance of its state with the pose of each vote a tentative line was first seen in, a
stochastic clone's (Roumeliotis & Burdick 2002) without the clone in the state: ``C = P[:, POSE]``
at the vote, then ``C <- F C`` at each prediction (``Phi`` at the flush) and ``C <- (I - K H) C``
at each update with that update's gain, a new landmark's rows ``G_pose C[POSE]``; a clone is
dropped with the last tentative line that needs it.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from filterpy.kalman import ExtendedKalmanFilter

from sonarslam.features.geometry import (
    FLIP_RHO,
    FloatArray,
    compose,
    compose_jacobians,
    line_difference,
    normalize_line,
    wrap_angle,
)
from sonarslam.features.line import LineFeature, check_mounting
from sonarslam.features.pose_source import PoseSource
from sonarslam.settings import bounded
from sonarslam.slam.backends.base import (
    AnchoredOdometry,
    BackendConfig,
    VoteObservations,
    ids_of_features,
    vote_observations,
)
from sonarslam.slam.backends.learned import LearnedNoise
from sonarslam.slam.io.states import HEADING_ERROR_FILE, write_heading_error
from sonarslam.slam.io.trajectory import Trajectory
from sonarslam.slam.mapping.landmarks import LandmarkMap
from sonarslam.slam.mapping.vote import AfterVote, Belief, Decision, LandmarkBelief, ViewPair
from sonarslam.slam.model.calibration import line_prediction_calibrated, world_line_calibrated
from sonarslam.slam.model.lines import line_prediction, world_observation
from sonarslam.slam.model.motion import MotionStep, step_displacement
from sonarslam.slam.model.noise import robust_kernel
from sonarslam.sonar.beam import Mounting

__all__ = [
    "EkfConfig",
    "LineEkf",
    "POSE",
    "YAW",
    "AHRS_BIAS",
    "MISALIGNMENT",
    "DVL_SCALE",
    "GYRO_BIAS",
    "N_VEHICLE",
    "CalibrationIndex",
    "MERGE_VARIANCE",
    "scalar_joseph_update",
]

# The vehicle's block of the state (module docstring); the landmarks' lines follow it.
POSE = slice(0, 3)  # x, y, psi: wTb
YAW = 2  # psi
AHRS_BIAS = 3  # b
MISALIGNMENT = 4  # delta
DVL_SCALE = 5  # k
GYRO_BIAS = 6  # g
N_VEHICLE = 7
HEADING = [YAW, AHRS_BIAS]  # what the AHRS measures: psi + b


@dataclass(frozen=True)
class CalibrationIndex:
    """Where the sonar's calibration states sit in the state (:meth:`LineEkf.calibration_index`).

    Attributes
    ----------
    mount : slice or None
        The mounting ``bTs`` ``(x_m, y_m, yaw_rad)``; None: not estimated.
    scale : int or None
        The range scale ``s``; None: not estimated.
    size : int
        The vehicle block's size with them (``N_VEHICLE`` when neither is estimated).
    """

    mount: slice | None
    scale: int | None
    size: int

    @classmethod
    def of(cls, estimate_mount: bool, estimate_scale: bool) -> CalibrationIndex:
        i = N_VEHICLE
        mount = slice(i, i + 3) if estimate_mount else None
        i += 3 * estimate_mount
        scale = i if estimate_scale else None
        return cls(mount, scale, i + int(estimate_scale))


#: The variance (m^2 and rad^2) of the exact update that ties two landmarks found to be one
#: wall: the same line, numerically.
MERGE_VARIANCE = 1e-10


def _filter(x: FloatArray, P: FloatArray) -> ExtendedKalmanFilter:
    """filterpy's EKF over the state ``x`` (n,) with covariance ``P`` (n, n); a new one when
    the state grows or shrinks (a landmark added or merged), as filterpy's are of fixed size.
    Its measurement size is not used: every update gives ``z``, ``H`` and ``R`` as arrays."""
    kf = ExtendedKalmanFilter(dim_x=x.size, dim_z=2)
    kf.x = x
    kf.P = P
    return kf


def scalar_joseph_update(
    x: FloatArray, P: FloatArray, h: FloatArray, nu: float, r: float
) -> tuple[FloatArray, FloatArray]:
    """The Kalman update by one scalar measurement, Joseph form, in O(n^2).

    With ``a = P h``, ``s = h^T a + r`` and the gain ``k = a / s``, the Joseph form
    ``(I - k h^T) P (I - k h^T)^T + r k k^T`` expands (P symmetric) to
    ``P - (k a^T + a k^T) + s k k^T``: two outer products instead of two n x n x n products,
    and exactly symmetric when P is (Simon 2006, eq. 5.19, for the Joseph form).

    Parameters
    ----------
    x : ndarray, shape (n,)
        State.
    P : ndarray, shape (n, n)
        Its covariance (symmetric).
    h : ndarray, shape (n,)
        The measurement's Jacobian row, ``z = h^T x + v``.
    nu : float
        The innovation ``z - h(x)`` (already wrapped for an angle).
    r : float
        The measurement's variance.

    Returns
    -------
    x, P : ndarray, shapes (n,), (n, n)
        The updated state and covariance (new arrays).
    """
    a = P @ h
    s = float(h @ a) + r
    k = a / s
    ka = np.outer(k, a)
    return x + k * nu, P - (ka + ka.T) + s * np.outer(k, k)


@dataclass(frozen=True)
class EkfConfig(BackendConfig):
    """Settings of the EKF: those of :class:`sonarslam.slam.backends.base.BackendConfig` and the
    following.

    Attributes
    ----------
    side_gate : bool
        As :class:`sonarslam.slam.mapping.landmarks.LandmarkConfig`, on as there: without it
        the EKF paired a wall's observations with the parallel face 4.9 m behind it (the
        choice's measurements: docs/research/consistency.md).
    first_estimates_jacobians : bool
        FEJ-EKF: line Jacobians at the landmarks' first estimates (consistency; see
        :meth:`LineEkf.predict_line`).
    gyro_bias_sigma_deg_per_s : float
        Prior 1-sigma of the gyro's constant yaw-rate bias ``g`` (deg/s); used only on steps
        that integrate the gyro (``[motion] yaw_rate_source = "gyro"``); why its default:
        docs/design-decisions.md.
    """

    side_gate: bool = True
    first_estimates_jacobians: bool = True
    gyro_bias_sigma_deg_per_s: float = bounded(1.0, 1e-6, 90.0)


class LineEkf:
    """EKF-SLAM with line landmarks; see the module docstring for the state.

    Parameters
    ----------
    t0_s : float
        Start time (Unix s).
    wTb0 : ndarray, shape (3,)
        Start pose.
    P0 : ndarray, shape (3, 3)
        Start pose covariance; its position block is used (the heading's is the AHRS's white
        noise and bias as the configuration models them).
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
        self._cal = CalibrationIndex.of(config.estimate_sonar_mount, config.range_scale_sigma > 0)
        nv = self._cal.size
        x = np.zeros(nv)
        x[POSE] = wTb0
        P = np.zeros((nv, nv))
        P[:2, :2] = P0[:2, :2]
        var_b = np.deg2rad(config.noise.ahrs_bias_sigma_deg) ** 2
        # psi0 came from the AHRS, which measures psi + b (white noise and bias as this filter
        # models them, not P0's heading): psi and b are anti-correlated.
        P[YAW, YAW] = np.deg2rad(config.noise.ahrs_white_sigma_deg) ** 2 + var_b
        P[AHRS_BIAS, AHRS_BIAS] = var_b
        P[YAW, AHRS_BIAS] = P[AHRS_BIAS, YAW] = -var_b
        P[MISALIGNMENT, MISALIGNMENT] = (
            np.deg2rad(config.misalignment_sigma_deg) ** 2 if config.estimate_misalignment else 0.0
        )
        P[DVL_SCALE, DVL_SCALE] = config.noise.dvl_scale_sigma**2
        P[GYRO_BIAS, GYRO_BIAS] = np.deg2rad(config.gyro_bias_sigma_deg_per_s) ** 2
        self._calibration_prior(x, P)
        self.kf = _filter(x, P)
        # the steps since the last flush: their Jacobians' product (vehicle block), pending
        # on the vehicle-landmark block of P (:meth:`_flush`)
        self._Phi = np.eye(nv)
        self._F = np.eye(nv)  # one step's Jacobian, rewritten in place
        self._pending = False
        self._h_heading = np.zeros(nv)  # z = psi + b
        self._h_heading[HEADING] = 1.0
        self.map = LandmarkMap(config, self.bTs)
        self._index: dict[int, int] = {}  # landmark id -> index of its rho in the state
        self._first_line_w: dict[int, FloatArray] = {}  # each landmark's first estimate (FEJ)
        self._kernel = robust_kernel(config.robust, config.robust_k)
        self._var_walk = np.deg2rad(config.noise.ahrs_bias_walk_deg_per_sqrt_s) ** 2  # rad^2/s
        if "scans" in config.learned_kinds:
            raise ValueError("learn_noise: the EKF takes no scans to learn their scale from")
        #: the noise learned from the innovations (``learn_noise``), or the configured one
        self.noise = LearnedNoise.of(config)
        self.noise.advance(t0_s, wTb0)
        self.noise_changes = 0  # steps of the learner that changed a value
        self.heading_error: list[tuple[float, float, float]] = []  # (t, b rad, var rad^2)
        self._pose_lin = np.zeros(3)  # the pose the vote's Jacobians are taken at (FEJ)
        self._cal_lin = (self.bTs.copy(), 1.0)  # and the calibration (mounting, range scale)
        self._xy_first = (float(wTb0[0]), float(wTb0[1]))  # the position as first predicted
        self._last_ahrs_t = -np.inf
        self._own_stats = {"ahrs_updates": 0}
        self._gyro_s = 0.0  # how long the heading has integrated the gyro
        #: wall time of each :meth:`update_lines` (s)
        self.vote_wall_s: list[float] = []
        self._after: AfterVote | None = None  # the estimate after the last vote's update
        #: every AHRS heading update's innovation ``(t_s, nu_rad, S_rad2)`` before the update
        self.heading_innovations: list[tuple[float, float, float]] = []
        # the poses of the votes that tentative lines were first seen in: vote number ->
        # (the pose then (3,), its covariance then (3, 3), Cov(state now, pose then) (n, 3))
        self._clones: dict[int, tuple[FloatArray, FloatArray, FloatArray]] = {}
        self._votes = 0

    # -- state access ----------------------------------------------------------------------

    @property
    def x(self) -> FloatArray:
        return np.asarray(self.kf.x)

    @property
    def P(self) -> FloatArray:
        """The full covariance, up to date (:meth:`_flush`)."""
        self._flush()
        return np.asarray(self.kf.P)

    @property
    def pose(self) -> FloatArray:
        return np.array(self.kf.x[POSE])

    @property
    def pose_cov(self) -> FloatArray:
        # the vehicle block is propagated at every step: no flush needed
        return np.asarray(self.kf.P[POSE, POSE]).copy()

    def calibration_index(self) -> CalibrationIndex:
        """Where the sonar's calibration states are (none when not estimated)."""
        return self._cal

    @property
    def sonar_mount(self) -> FloatArray:
        """The sonar mounting ``bTs`` ``(x_m, y_m, yaw_rad)`` the filter predicts with: its
        estimate when estimated, else the dataset's."""
        m = self._cal.mount
        return self.bTs.copy() if m is None else np.array(self.kf.x[m])

    @property
    def range_scale(self) -> float:
        """The sonar's range scale the filter predicts with (1 when not estimated)."""
        i = self._cal.scale
        return 1.0 if i is None else float(self.kf.x[i])

    def _calibration_prior(self, x: FloatArray, P: FloatArray) -> None:
        """The calibration states' prior means and covariance, in place (module docstring)."""
        cfg, m, i = self.config, self._cal.mount, self._cal.scale
        if m is not None:
            x[m] = self.bTs
            var_xy = cfg.sonar_mount_sigma_m**2
            var_yaw = np.deg2rad(cfg.sonar_mount_sigma_deg) ** 2
            P[m, m] = np.diag([var_xy, var_xy, var_yaw])
            if cfg.sonar_yaw_prior == "dead_reckoning" and cfg.estimate_misalignment:
                # the prior is on yaw - delta (its variance var_yaw) with delta's own: yaw =
                # delta + e, so Var(yaw) = var_yaw + var_delta, Cov(yaw, delta) = var_delta
                yaw = m.start + 2
                P[yaw, yaw] += P[MISALIGNMENT, MISALIGNMENT]
                P[yaw, MISALIGNMENT] = P[MISALIGNMENT, yaw] = P[MISALIGNMENT, MISALIGNMENT]
        if i is not None:
            x[i] = 1.0
            P[i, i] = cfg.range_scale_sigma**2

    @property
    def stats(self) -> dict[str, int]:
        return {**self.map.stats, **self._own_stats}

    def index(self, landmark_id: int) -> int:
        """Index of landmark ``landmark_id``'s ``rho`` in the state (active landmarks only)."""
        return self._index[landmark_id]

    def landmark_line(self, landmark_id: int) -> FloatArray:
        i = self.index(landmark_id)
        return self.x[i : i + 2].copy()

    # -- prediction ------------------------------------------------------------------------

    def predict(self, step: MotionStep) -> FloatArray:
        """Integrate one motion step (:mod:`sonarslam.slam.model.motion`) on the pose block.

        Returns the relative motion ``bTb'`` of this step (the odometry the front end chains).
        """
        if step.dt_s <= 0.0:
            return np.zeros(3)
        self.noise.see_step(step)
        x = self.kf.x
        psi, delta, k_scale = float(x[2]), float(x[4]), float(x[5])
        sx, sy = step.dx_m, step.dy_m
        lever_bias = step.dx_dbias_m_s != 0.0 or step.dy_dbias_m_s != 0.0
        if lever_bias:  # the DVL lever arm's term turns with the gyro's rate, bias and all
            g = float(x[GYRO_BIAS])
            sx, sy = sx + g * step.dx_dbias_m_s, sy + g * step.dy_dbias_m_s
        dx, dy = step_displacement(psi + delta, sx, sy)
        gain = 1.0 + k_scale
        x[0] += gain * dx
        x[1] += gain * dy
        dyaw = step.dyaw_rad - step.gyro_dt_s * float(x[GYRO_BIAS])
        x[2] = wrap_angle(psi + dyaw)
        self._gyro_s += step.gyro_dt_s
        # d p' / d psi = J (p' - p): with first-estimate Jacobians, p is the position this step
        # started from as it was first predicted, not as the updates since have moved it (Huang,
        # Mourikis & Roumeliotis 2008, eq. 23): the filter then gains no information on the
        # unobservable rotation of the whole map and trajectory (the AHRS bias's direction)
        x0, x1 = float(x[0]), float(x[1])
        if self.config.first_estimates_jacobians:
            jx, jy = x0 - self._xy_first[0], x1 - self._xy_first[1]
        else:
            jx, jy = gain * dx, gain * dy
        self._xy_first = (x0, x1)
        F = self._F
        F[0, 2] = -jy
        F[1, 2] = jx
        if self.config.estimate_misalignment:
            F[0, 4] = -jy
            F[1, 4] = jx
        F[0, 5] = dx
        F[1, 5] = dy
        F[2, GYRO_BIAS] = -step.gyro_dt_s
        if lever_bias:
            bx, by = step_displacement(psi + delta, step.dx_dbias_m_s, step.dy_dbias_m_s)
            F[0, GYRO_BIAS] = gain * bx
            F[1, GYRO_BIAS] = gain * by
        else:
            F[0, GYRO_BIAS] = F[1, GYRO_BIAS] = 0.0
        # the vehicle block now (P_vv <- F P_vv F^T + Q); the landmark columns at the flush
        nv = self._cal.size
        P_vv = self.kf.P[:nv, :nv]
        P_vv[...] = F @ P_vv @ F.T
        P_vv[0, 0] += step.var_xy_m2
        P_vv[1, 1] += step.var_xy_m2
        P_vv[2, 2] += step.var_yaw_rad2(self.config.noise.gyro_sigma_rad_per_s)
        self._walks(P_vv, step)
        self._Phi = F @ self._Phi
        self._pending = True
        self.t_s = step.t_s
        bx, by = step_displacement(delta, sx, sy)  # delta and k
        return np.array([gain * bx, gain * by, dyaw])

    def _walks(self, P_vv: FloatArray, step: MotionStep) -> None:
        """The random walks' process noise of one step, in place on the vehicle block: the
        AHRS heading error's ``q dt`` and the DVL scale's (the configured or, when learned, the
        learned value, :class:`sonarslam.slam.backends.learned.LearnedNoise`, which learns the
        heading walk only where the gyro turns the heading)."""
        dt = step.dt_s
        P_vv[AHRS_BIAS, AHRS_BIAS] += self.noise.value("heading_walk") * dt
        P_vv[DVL_SCALE, DVL_SCALE] += self.noise.value("dvl_scale_walk") * dt

    def _flush(self) -> None:
        """Apply the batched steps' Jacobian product to the vehicle-landmark block of P:
        ``P_vl <- Phi P_vl`` (and its transpose), which the steps one by one would have
        done ``F_k ... F_1 P_vl``; equal to round-off."""
        if not self._pending:
            return
        P = self.kf.P
        V = self._cal.size
        if P.shape[0] > V:
            P[:V, V:] = self._Phi @ P[:V, V:]
            P[V:, :V] = P[:V, V:].T
        for _, _, C in self._clones.values():
            C[:V] = self._Phi @ C[:V]
        self._Phi = np.eye(V)
        self._pending = False

    # -- updates ---------------------------------------------------------------------------

    def _update(
        self,
        z: FloatArray,
        H: FloatArray,
        hx: FloatArray,
        R: FloatArray,
        residual: Callable[[Any, Any], Any],
    ) -> None:
        self._flush()
        self.kf.update(z, lambda _x: H, lambda _x: hx, R=R, residual=residual)
        K = np.asarray(self.kf.K)
        for _, _, C in self._clones.values():
            C -= K @ (H @ C)

        # filterpy's Joseph form (I - K H) P (I - K H)^T + K R K^T is symmetric only to
        # round-off, and nothing else symmetrises P: over hundreds of updates of a filter
        # whose variances span 1e-8 to 1e2 the asymmetry grows until P is indefinite, a gate's
        # squared Mahalanobis distance goes negative and any pairing passes it (docs/research/consistency.md)
        P = self.kf.P
        P[...] = 0.5 * (P + P.T)
        self._normalise()

    def _normalise(self) -> None:
        """Wrap the heading and keep the landmarks normalised, the covariance alike: a flip of
        ``rho``'s sign (``FLIP_RHO``) negates its row and column of P."""
        x = self.kf.x
        x[YAW] = wrap_angle(x[YAW])
        if not self._index:
            return
        i = np.fromiter(self._index.values(), dtype=np.int64, count=len(self._index))
        for j in i[x[i] < 0.0]:
            self.kf.P[j, :] *= -1.0
            self.kf.P[:, j] *= -1.0
            for _, _, C in self._clones.values():
                C[j] *= -1.0
        x[i], x[i + 1] = normalize_line(x[i], x[i + 1])

    def update_heading(self, t_s: float, yaw_body_rad: float) -> bool:
        """AHRS heading update (``z = psi + b``), at most every ``ahrs_period_s``."""
        if t_s - self._last_ahrs_t < self.config.ahrs_period_s:
            return False
        self._last_ahrs_t = t_s
        self._flush()
        x, P = self.kf.x, self.kf.P
        r = float(np.deg2rad(self.config.noise.ahrs_white_sigma_deg) ** 2)
        nu = float(wrap_angle(yaw_body_rad - (float(x[YAW]) + float(x[AHRS_BIAS]))))
        S = float(P[YAW, YAW] + 2.0 * P[YAW, AHRS_BIAS] + P[AHRS_BIAS, AHRS_BIAS] + r)
        self.heading_innovations.append((t_s, nu, S))
        h = np.zeros(x.size)
        h[: self._cal.size] = self._h_heading

        if self._clones:
            k = P @ h / (float(h @ P @ h) + r)  # the gain scalar_joseph_update applies
            for _, _, C in self._clones.values():
                C -= np.outer(k, h @ C)
        self.kf.x, self.kf.P = scalar_joseph_update(x, P, h, nu, r)
        self._normalise()
        self._own_stats["ahrs_updates"] += 1
        self.noise.advance(t_s, self.kf.x[POSE])
        if self._var_walk > 0.0 or self.noise.learns("heading_walk"):
            # the filtered heading error's track (heading_error.csv)
            b = self.kf.x[AHRS_BIAS]
            self.heading_error.append((t_s, float(b), float(self.kf.P[AHRS_BIAS, AHRS_BIAS])))
        return True

    def predict_line(self, landmark_id: int) -> tuple[FloatArray, FloatArray]:
        """Predicted observation of a landmark in the sonar frame and its full Jacobian (2, n).

        With ``first_estimates_jacobians`` the Jacobian is evaluated at the landmark's first
        estimate and at the pose of this vote's start, as the FEJ-EKF of Huang, Mourikis &
        Roumeliotis (2008): without it the filter gains spurious information on the
        unobservable global heading and becomes overconfident.
        """
        if self.config.calibrated:
            return self._predict_line_calibrated(landmark_id)
        z_hat, H_pose, H_line = line_prediction(
            self.x[POSE], self.landmark_line(landmark_id), self.bTs
        )
        if self.config.first_estimates_jacobians:
            z_lin, H_pose, H_line = line_prediction(
                self._pose_lin, self._first_line_w[landmark_id], self.bTs
            )
            if line_difference(z_lin, z_hat)[1]:  # the same line seen from the other side of 0
                H_pose, H_line = FLIP_RHO @ H_pose, FLIP_RHO @ H_line
        H = np.zeros((2, self.x.size))
        H[:, POSE] = H_pose
        i = self.index(landmark_id)
        H[:, i : i + 2] = H_line
        return z_hat, H

    def _predict_line_calibrated(self, landmark_id: int) -> tuple[FloatArray, FloatArray]:
        """:meth:`predict_line` with the sonar's calibration states
        (:func:`sonarslam.slam.model.calibration.line_prediction_calibrated`); with first-estimate
        Jacobians, the calibration's are taken at its estimate at this vote's start."""
        line = self.landmark_line(landmark_id)
        z_hat, H_pose, H_line, H_mount, H_scale = line_prediction_calibrated(
            self.x[POSE], line, self.sonar_mount, self.range_scale
        )
        if self.config.first_estimates_jacobians:
            z_lin, H_pose, H_line, H_mount, H_scale = line_prediction_calibrated(
                self._pose_lin, self._first_line_w[landmark_id], *self._cal_lin
            )
            if line_difference(z_lin, z_hat)[1]:  # the same line seen from the other side of 0
                H_pose, H_line = FLIP_RHO @ H_pose, FLIP_RHO @ H_line
                H_mount, H_scale = FLIP_RHO @ H_mount, FLIP_RHO @ H_scale
        H = np.zeros((2, self.x.size))
        H[:, POSE] = H_pose
        if self._cal.mount is not None:
            H[:, self._cal.mount] = H_mount
        if self._cal.scale is not None:
            H[:, self._cal.scale] = H_scale[:, 0]
        i = self.index(landmark_id)
        H[:, i : i + 2] = H_line
        return z_hat, H

    def update_lines(self, features: list[LineFeature]) -> list[int | None]:
        """One vote of lines: this filter's belief to the landmark layer, which decides the
        associations and new landmarks (:meth:`sonarslam.slam.mapping.landmarks.LandmarkMap.vote`); the
        decision applied here. The landmark id of each feature (None: not associated)."""
        wall0 = time.perf_counter()
        obs = vote_observations(features, self.config, self.map.line_cov_scale)
        decision = self.map.vote(self._belief(obs))
        self._apply(decision)
        if self.noise.on and obs.features:
            self._learn([new.id for new in decision.new_landmarks])
        live = {c.view for c in self.map.tentative}
        self._clones = {v: c for v, c in self._clones.items() if v in live}
        self.vote_wall_s.append(time.perf_counter() - wall0)
        return ids_of_features(features, obs.features, decision.ids)

    def _learn(self, new_landmarks: list[int]) -> None:
        """This vote's innovations into the noise learner; the line covariance scale it learned
        in force from the next vote on."""
        self.noise.advance(self.t_s, self.x[POSE])
        if self.noise.take_lines(self.map, new_landmarks):
            self.noise_changes += 1
            self.map.line_cov_scale = self.config.line_cov_scale * self.noise.value("line_scale")

    def _belief(self, obs: VoteObservations) -> Belief:
        """Every active landmark predicted from the whole state (the Jacobians at this vote's
        start, :meth:`predict_line`)."""
        ids = list(self._index) if obs.features else []
        view = None
        if obs.features:
            self._pose_lin = self.x[POSE].copy()
            self._cal_lin = (self.sonar_mount, self.range_scale)
            if self.config.tentative_joint_gate:
                self._votes += 1
                view = self._votes
                P = self.P
                self._clones[view] = (self.pose, P[POSE, POSE].copy(), P[:, POSE].copy())
        preds = [self.predict_line(j) for j in ids]
        return Belief(
            features=obs.features,
            rejected_near=obs.rejected_near,
            z=obs.z,
            R=obs.R,
            wTb=self.pose,
            P_pose=self.pose_cov,
            anchor=None,
            candidates=ids,
            z_hat=np.array([p[0] for p in preds]).reshape(-1, 2),
            H=np.array([p[1] for p in preds]).reshape(-1, 2, self.x.size),
            P=self.P,
            landmarks=LandmarkBelief({j: self.landmark_line(j) for j in ids}),
            seeds_used=False,
            after_previous=self._after,
            view=view,
            view_pairs=self._view_pairs(view) if view is not None else None,
        )

    def _view_pairs(self, view: int) -> dict[object, ViewPair]:
        """:meth:`_view_pair` of every vote a tentative line waits on, and of this one's
        ``view`` (a tentative line first seen earlier in this vote)."""
        views = {c.view for c in self.map.tentative if c.view is not None} | {view}
        pairs = {v: self._view_pair(v) for v in views}
        return {v: p for v, p in pairs.items() if p is not None}

    def _view_pair(self, view: object) -> ViewPair | None:
        """The sonar's pose now and at vote ``view`` (as estimated then), with their joint
        covariance from the clone's cross-covariance (module docstring); None when no clone."""
        clone = self._clones.get(view) if isinstance(view, int) else None
        if clone is None:
            return None
        wTb_then, P_then, C = clone
        P = self.P  # flushed: the clones' vehicle rows are current too
        cov_b = np.block([[P[POSE, POSE], C[POSE]], [C[POSE].T, P_then]])
        wTb_now = self.pose
        J = np.zeros((6, 6))
        J[:3, :3] = compose_jacobians(wTb_now, self.bTs)[0]
        J[3:, 3:] = compose_jacobians(wTb_then, self.bTs)[0]
        return ViewPair(compose(wTb_now, self.bTs), compose(wTb_then, self.bTs), J @ cov_b @ J.T)

    def _apply(self, decision: Decision) -> None:
        """The landmark layer's decision: the merges, the updates, the new landmarks; then the
        estimate after them for the layer (the next belief's ``after_previous``)."""
        for keep, drop in decision.merges:
            self._merge_landmarks(keep, drop)
        for j, f in decision.updates:
            self._update_line(j, f)
        for new in decision.new_landmarks:
            self._add_landmark(new.id, new.observations[-1][1])
        if decision.ids:
            self._after = AfterVote(self.pose, self._landmark_belief(decision.seen))

    def _landmark_belief(self, seen: list[int]) -> LandmarkBelief:
        """The lines of ``seen``; of every active landmark, with their joint covariance, when
        the landmark layer merges duplicates."""
        if self.config.merge_gate_probability is None:
            return LandmarkBelief({j: self.landmark_line(j) for j in seen})
        ids = list(self._index)
        cov = self.landmark_covariance(ids) if ids else None
        return LandmarkBelief({j: self.landmark_line(j) for j in ids}, ids, cov)

    def _update_line(self, landmark_id: int, f: LineFeature) -> None:
        """One associated observation's update, linearised at the state the previous one left;
        with a robust kernel its covariance is divided by the kernel's weight of its
        innovation's Mahalanobis distance (:class:`sonarslam.slam.backends.base.BackendConfig`)."""
        z_hat, H = self.predict_line(landmark_id)
        nu, flipped = line_difference(f.z, z_hat)
        R = np.asarray(f.cov) * self.map.line_cov_scale
        R = FLIP_RHO @ R @ FLIP_RHO if flipped else R
        if self._kernel is not None:
            d = float(np.sqrt(nu @ np.linalg.solve(H @ self.P @ H.T + R, nu)))
            R = R / self._kernel.weight(d)
        self._update(f.z, H, z_hat, R, lambda a, b: line_difference(a, b)[0])

    def _add_landmark(self, landmark_id: int, f: LineFeature) -> None:
        """Augment the state with the world line of ``f`` (the newest observation of a promoted
        line; the earlier, tentative ones only seeded it) and the full cross-covariances."""
        if self.config.calibrated:
            self._add_landmark_calibrated(landmark_id, f)
            return
        obs = world_observation(f, self.x[POSE], self.P[POSE, POSE], self.bTs)
        x, P = self.x, self.P
        n = x.size
        P_new = np.zeros((n + 2, n + 2))
        P_new[:n, :n] = P
        cross = obs.G_pose @ P[POSE, :]  # (2, n)
        P_new[n:, :n] = cross
        P_new[:n, n:] = cross.T
        R = np.asarray(f.cov) * self.map.line_cov_scale
        P_new[n:, n:] = obs.G_pose @ P[POSE, POSE] @ obs.G_pose.T + obs.G_z @ R @ obs.G_z.T
        self.kf = _filter(np.concatenate([x, obs.line_w]), P_new)
        for v, (pose, P_then, C) in self._clones.items():
            self._clones[v] = (pose, P_then, np.vstack([C, obs.G_pose @ C[POSE]]))
        self._index[landmark_id] = n
        self._first_line_w[landmark_id] = obs.line_w.copy()

    def _add_landmark_calibrated(self, landmark_id: int, f: LineFeature) -> None:
        """:meth:`_add_landmark` with the sonar's calibration states: the world line at the
        current estimate of the pose and the calibration
        (:func:`sonarslam.slam.model.calibration.world_line_calibrated`), its cross-covariances
        through all of them."""
        check_mounting([f], self.bTs, "LineEkf (the dataset's sonar mounting)")
        x, P = self.x, self.P
        n = x.size
        line_w, G_z, G_pose, G_mount, G_scale = world_line_calibrated(
            np.asarray(f.z, dtype=np.float64), x[POSE], self.sonar_mount, self.range_scale
        )
        nv = self._cal.size
        G = np.zeros((2, nv))  # d line_w / d the vehicle block
        G[:, POSE] = G_pose
        if self._cal.mount is not None:
            G[:, self._cal.mount] = G_mount
        if self._cal.scale is not None:
            G[:, self._cal.scale] = G_scale[:, 0]
        P_new = np.zeros((n + 2, n + 2))
        P_new[:n, :n] = P
        cross = G @ P[:nv, :]  # (2, n)
        P_new[n:, :n] = cross
        P_new[:n, n:] = cross.T
        R = np.asarray(f.cov) * self.map.line_cov_scale
        P_new[n:, n:] = G @ P[:nv, :nv] @ G.T + G_z @ R @ G_z.T
        self.kf = _filter(np.concatenate([x, line_w]), P_new)
        for v, (pose, P_then, C) in self._clones.items():
            self._clones[v] = (pose, P_then, np.vstack([C, G @ C[:nv]]))
        self._index[landmark_id] = n
        self._first_line_w[landmark_id] = line_w.copy()

    def landmark_covariance(self, landmark_ids: list[int]) -> FloatArray:
        """Joint covariance of these landmarks' lines, shape (2k, 2k)."""
        idx = np.concatenate([[self.index(j), self.index(j) + 1] for j in landmark_ids])
        return self.P[np.ix_(idx, idx)].copy()

    def _merge_landmarks(self, keep: int, drop: int) -> None:
        """Tie ``drop`` to ``keep`` by an exact update on their difference, then take ``drop``
        out of the state (its information is in ``keep`` and the cross-covariances now)."""
        ik, idr = self.index(keep), self.index(drop)
        nu, flipped = line_difference(self.x[idr : idr + 2], self.x[ik : ik + 2])
        H = np.zeros((2, self.x.size))
        H[:, ik : ik + 2] = -np.eye(2)
        H[:, idr : idr + 2] = FLIP_RHO if flipped else np.eye(2)
        R = np.eye(2) * MERGE_VARIANCE
        self._update(np.zeros(2), H, nu, R, lambda a, b: a - b)
        keep_rows = np.r_[0:idr, idr + 2 : self.x.size]
        self.kf = _filter(self.x[keep_rows].copy(), self.P[np.ix_(keep_rows, keep_rows)].copy())
        for v, (pose, P_then, C) in self._clones.items():
            self._clones[v] = (pose, P_then, C[keep_rows])
        del self._index[drop], self._first_line_w[drop]
        self._index = {j: i - 2 if i > idr else i for j, i in self._index.items()}

    # -- results (slam.backends.base.Backend) ----------------------------------------------

    def pose_source(self, odometry: AnchoredOdometry) -> PoseSource:
        """The driver's odometry anchored at this filter's estimate."""
        return odometry

    def finish(self) -> None:
        pass

    def map_records(self) -> list[dict[str, object]]:
        """Per active landmark: id, rho, theta, cov, world endpoints, observation count."""
        return self.map.records(
            {j: (self.landmark_line(j), self.landmark_covariance([j])) for j in self._index},
            self._after,
        )

    def trajectories(self, batch: bool = False) -> dict[str, Trajectory]:
        return {}

    def metrics(self) -> dict[str, float | int]:
        """The final estimates of the vehicle's constants with their sd (``state_*``): the AHRS
        bias (deg), and when estimated the DVL misalignment (deg) and scale ``k`` (the vehicle
        moves ``1 + k`` times the DVL's velocity)."""
        x, P = self.x, self.P
        out: dict[str, float | int] = {
            "state_ahrs_bias_deg": float(np.rad2deg(x[AHRS_BIAS])),
            "state_ahrs_bias_sd_deg": float(np.rad2deg(np.sqrt(P[AHRS_BIAS, AHRS_BIAS]))),
        }
        if self.config.estimate_misalignment:
            out["state_misalignment_deg"] = float(np.rad2deg(x[MISALIGNMENT]))
            sd = np.sqrt(P[MISALIGNMENT, MISALIGNMENT])
            out["state_misalignment_sd_deg"] = float(np.rad2deg(sd))
        if self.config.noise.dvl_scale_sigma > 0.0 or self.noise.learns("dvl_scale_walk"):
            out["state_dvl_scale"] = float(x[DVL_SCALE])
            out["state_dvl_scale_sd"] = float(np.sqrt(P[DVL_SCALE, DVL_SCALE]))
        if self._gyro_s > 0.0:
            out["state_gyro_bias_deg_per_s"] = float(np.rad2deg(x[GYRO_BIAS]))
            out["state_gyro_bias_sd_deg_per_s"] = float(
                np.rad2deg(np.sqrt(P[GYRO_BIAS, GYRO_BIAS]))
            )
        return out | self._calibration_metrics(x, P) | self.noise.metrics()

    def _calibration_metrics(self, x: FloatArray, P: FloatArray) -> dict[str, float | int]:
        """The sonar's calibration estimates with their sd, under the factor graph's keys
        (``state_sonar_{x,y}{,_sd}_m``, ``state_sonar_yaw{,_sd}_deg``,
        ``state_sonar_range_scale{,_sd}``, and with the misalignment the correlation
        ``state_sonar_yaw_misalignment_corr``); none when not estimated."""
        out: dict[str, float | int] = {}
        m, i = self._cal.mount, self._cal.scale
        if m is not None:
            sd = np.sqrt(np.diag(P)[m])
            for k, (name, f) in enumerate((("x_m", 1.0), ("y_m", 1.0), ("yaw_deg", 180 / np.pi))):
                base, unit = name.rsplit("_", 1)
                out[f"state_sonar_{base}_{unit}"] = f * float(x[m][k])
                out[f"state_sonar_{base}_sd_{unit}"] = f * float(sd[k])
            if self.config.estimate_misalignment:
                yaw = m.start + 2
                corr = P[yaw, MISALIGNMENT] / np.sqrt(P[yaw, yaw] * P[MISALIGNMENT, MISALIGNMENT])
                out["state_sonar_yaw_misalignment_corr"] = float(corr)
        if i is not None:
            out["state_sonar_range_scale"] = float(x[i])
            out["state_sonar_range_scale_sd"] = float(np.sqrt(P[i, i]))
        return out

    def save(self, out_dir: Path) -> list[Path]:
        """The filtered AHRS heading error's track ``heading_error.csv`` when it walks
        (:mod:`sonarslam.slam.io.states`) and the learned noise's ``noise.csv`` when the loop
        learns it (:mod:`sonarslam.slam.backends.learned`); nothing else."""
        out = self.noise.save(Path(out_dir))
        if not self.heading_error:
            return out
        t, b, var = (np.array(c) for c in zip(*self.heading_error, strict=True))
        return [write_heading_error(Path(out_dir) / HEADING_ERROR_FILE, t, b, np.sqrt(var)), *out]
