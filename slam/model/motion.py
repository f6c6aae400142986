"""The motion model: DVL body velocity and a yaw rate (or the AHRS heading), integrated.

Frames: the DVL measures the velocity of its own point in its own frame; the body velocity
(x forward, y left) is ``v_b = R(dvl_yaw) v_dvl - omega x r`` with ``r`` the DVL's lever arm
(``(x_m, y_m)`` of its mounting) and ``omega`` the yaw rate the model turns by at that time
(:func:`body_velocity`, the one place of that conversion; the rigid-body lever-arm compensation of
Kinsey, Eustice & Whitcomb 2006, "A survey of underwater vehicle navigation", sec. 3). The AHRS gives
the yaw of its own frame; the body yaw is ``psi_b = psi_ahrs - ahrs_yaw`` (mountings in
:mod:`sonarslam.datasets.config`).

The model, one step of ``dt`` between two records::

    (x, y) += R(psi) (dt v_b)        psi += dt r        F = [[1, 0, -dy], [0, 1, dx], [0, 0, 1]]

with ``(dx, dy) = R(psi) dt v_b`` the step in the world (:func:`step_displacement`) and the
velocity noise counted once per held DVL sample (:func:`sonarslam.slam.model.noise.held_velocity_variance_step`).
The driver turns the sensor stream into one :class:`MotionStep` per record
(:func:`motion_step`), and every estimator integrates those same steps: the EKF's prediction,
the factor graph's odometry (:class:`RelativeMotion`), the odometry chain of the front end's
pose sources (:class:`OdometryChain`). Dead reckoning (:func:`dead_reckoning`) is the same
model with the heading taken from the AHRS instead of integrated, vectorised over a whole run.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt

from sonarslam.datasets.errors import DataError
from sonarslam.datasets.records import AttitudeSeries, DvlSeries
from sonarslam.features.geometry import FloatArray, transform_points, wrap_angle
from sonarslam.slam.io.trajectory import Trajectory
from sonarslam.slam.model.noise import (
    MotionNoise,
    dvl_sample_sigma,
    held_velocity_variance_step,
    held_velocity_variance_step_float,
)
from sonarslam.sonar.beam import Mounting

__all__ = [
    "body_velocity",
    "body_yaw",
    "yaw_rate_input",
    "MotionStep",
    "motion_step",
    "step_displacement",
    "RelativeMotion",
    "OdometryChain",
    "VelocityInput",
    "velocity_input",
    "dead_reckoning",
]


def body_velocity(
    v_dvl_mps: npt.ArrayLike, dvl_mounting: Mounting, yaw_rate_rad_per_s: npt.ArrayLike = 0.0
) -> FloatArray:
    """DVL-frame velocities (N, 2) to body-frame velocities (N, 2) (m/s), lever arm compensated.

    ``v_b = R(yaw_dvl) v_dvl - omega x r``: the DVL measures the velocity of its own point,
    which is the body origin's plus ``omega x r`` (a rigid body turning at ``omega`` about the
    vertical, ``r = (x_m, y_m)`` the mounting's lever arm; in 2-D ``omega x r = omega (-r_y,
    r_x)``); Kinsey, Eustice & Whitcomb 2006, "A survey of underwater vehicle navigation", sec. 3.

    Parameters
    ----------
    v_dvl_mps : array_like, shape (N, 2) or (2,)
        Velocities in the DVL frame (m/s).
    dvl_mounting : Mounting
        The DVL's ``bTs``: its yaw rotates, its ``(x_m, y_m)`` is the lever arm.
    yaw_rate_rad_per_s : float or array_like, shape (N,)
        The yaw rate the motion model turns by at each velocity's time (rad/s): the gyro's or
        the AHRS heading's own change (``[motion] yaw_rate_source``, :func:`yaw_rate_input`).
        0 gives the DVL's velocity in body axes. With no lever arm it is not used.
    """
    v = np.atleast_2d(np.asarray(v_dvl_mps, dtype=np.float64))
    c, s = np.cos(dvl_mounting.yaw_rad), np.sin(dvl_mounting.yaw_rad)
    v_b = np.column_stack([c * v[:, 0] - s * v[:, 1], s * v[:, 0] + c * v[:, 1]])
    rx, ry = dvl_mounting.x_m, dvl_mounting.y_m
    if rx == 0.0 and ry == 0.0:
        return v_b
    w = np.asarray(yaw_rate_rad_per_s, dtype=np.float64)
    v_b[:, 0] += w * ry  # - omega x r = -omega (-r_y, r_x)
    v_b[:, 1] -= w * rx
    return v_b


def yaw_rate_input(
    t_s: npt.ArrayLike,
    attitude: AttitudeSeries,
    ahrs_mounting: Mounting,
    yaw_rate_source: str,
    stale_s: float,
    ahrs_deviation_rad: tuple[float, float] = (0.0, 0.0),
) -> FloatArray:
    """The yaw rate the motion model turns by from each time on (rad/s), shape (N,), causal.

    The newest AHRS sample at or before ``t``: its gyro rate (``yaw_rate_source = "gyro"``) or
    the body heading's change from the sample before it over their time apart (``"heading"``);
    0 before the first sample, for the first sample with ``"heading"``, and when the newest
    sample is older than ``stale_s`` (an AHRS gap): the rate the closed loop
    (:func:`sonarslam.slam.run.closed_loop.run_closed_loop`) turns its heading by, which it keeps
    step by step from the samples it streams (so its first ``"heading"`` rate waits for its
    second sample, where this takes the sample before).
    """
    t = np.atleast_1d(np.asarray(t_s, dtype=np.float64))
    ta = attitude.t
    j = np.searchsorted(ta, t, side="right") - 1
    have = j >= 0
    jj = np.clip(j, 0, None)
    if yaw_rate_source == "gyro":
        rate_at = np.asarray(attitude.yaw_rate_rad_per_s, dtype=np.float64)
    elif yaw_rate_source == "heading":
        rate_at = np.zeros(ta.size)
        if ta.size > 1:
            yaw_b = body_yaw(attitude.yaw_rad, ahrs_mounting, ahrs_deviation_rad)
            dt = np.diff(ta)
            ok = dt > 0.0
            rate_at[1:][ok] = wrap_angle(np.diff(yaw_b)[ok]) / dt[ok]
    else:
        raise ValueError(f"yaw_rate_source must be 'gyro' or 'heading', got {yaw_rate_source!r}")
    if ta.size == 0:
        return np.zeros(t.size)
    fresh = have & (t - ta[jj] <= stale_s)
    return np.where(fresh, rate_at[jj], 0.0)


def body_yaw(
    yaw_ahrs_rad: npt.ArrayLike,
    ahrs_mounting: Mounting,
    deviation_rad: tuple[float, float] = (0.0, 0.0),
) -> FloatArray:
    """AHRS-frame yaw to body yaw (rad), wrapped.

    ``deviation_rad = (B, C)``: the AHRS yaw errs by ``B sin psi + C cos psi`` around the body
    yaw ``psi`` (a compass deflected by the vehicle's own field, hard iron); it is taken off,
    evaluated at the measured yaw (the error of that is second order in ``B``, ``C``).
    """
    psi = wrap_angle(np.asarray(yaw_ahrs_rad, dtype=np.float64) - ahrs_mounting.yaw_rad)
    b, c = deviation_rad
    if b == 0.0 and c == 0.0:
        return psi
    return wrap_angle(psi - (b * np.sin(psi) + c * np.cos(psi)))


@dataclass(frozen=True, slots=True)
class MotionStep:
    """The motion input of one step between two records, as every estimator integrates it.

    Attributes
    ----------
    t_s : float
        End of the step (Unix s).
    dt_s : float
        Its length (s), >= 0.
    dx_m, dy_m : float
        Displacement ``dt * v_b`` in the body frame at the step's start (m).
    dyaw_rad : float
        Heading change ``dt * r`` (rad).
    sigma_v_mps : float
        1-sigma of the held velocity, per axis (m/s).
    held_s : float
        How long the velocity sample has been held at the end of the step (s), >= ``dt_s``.
    var_yaw_gap_rad2 : float
        Heading variance the step adds because the AHRS is silent (rad^2): the growth of
        :meth:`sonarslam.slam.model.noise.MotionNoise.gap_heading_variance` over the step; 0 otherwise.
    gyro_dt_s : float
        How much of the step ``dyaw_rad`` integrates the gyro's rate over (s): ``dt_s`` when
        the rate is the gyro's, 0 when it is the AHRS heading's own change or none (an AHRS
        gap). A gyro bias ``g`` (rad/s) turns the true heading change into
        ``dyaw_rad - g * gyro_dt_s``.
    dx_dbias_m_s, dy_dbias_m_s : float
        The displacement's derivative by that bias (m per rad/s): the lever-arm term of
        :func:`body_velocity` turns with the gyro's rate, so the true displacement is
        ``(dx_m, dy_m) + g (dx_dbias_m_s, dy_dbias_m_s)`` = ``+ g gyro_dt_s (-r_y, r_x)``;
        0 without a lever arm or off the gyro.
    var_xy_m2 : float
        Derived: the position variance per axis the step adds, one error per held DVL sample
        (:func:`sonarslam.slam.model.noise.held_velocity_variance_step`, m^2).
    """

    t_s: float
    dt_s: float
    dx_m: float
    dy_m: float
    dyaw_rad: float
    sigma_v_mps: float
    held_s: float
    var_yaw_gap_rad2: float = 0.0
    gyro_dt_s: float = 0.0
    dx_dbias_m_s: float = 0.0
    dy_dbias_m_s: float = 0.0
    #: computed once: the driver's odometry and the back end both ask
    var_xy_m2: float = field(init=False)

    def __post_init__(self) -> None:
        var = held_velocity_variance_step_float(
            float(self.held_s), float(self.dt_s), float(self.sigma_v_mps)
        )
        object.__setattr__(self, "var_xy_m2", var)

    def var_yaw_rad2(self, gyro_sigma_rad_per_s: float) -> float:
        """Heading variance of the step (rad^2): a yaw-rate noise ``(dt sigma)^2`` (the back
        end's) plus the AHRS gap's (:attr:`var_yaw_gap_rad2`)."""
        return (self.dt_s * gyro_sigma_rad_per_s) ** 2 + self.var_yaw_gap_rad2

    @property
    def var_xy_white_m2(self) -> float:
        """The same with the velocity error independent at every step, ``(dt sigma)^2`` (m^2)."""
        return (self.dt_s * self.sigma_v_mps) ** 2


def motion_step(
    t_prev_s: float,
    t_s: float,
    v_b_mps: npt.ArrayLike,
    sigma_v_mps: float,
    yaw_rate_rad_per_s: float,
    held_from_s: float,
    var_yaw_gap_rad2: float = 0.0,
    from_gyro: bool = False,
    lever_arm_m: tuple[float, float] = (0.0, 0.0),
) -> MotionStep:
    """The step from ``t_prev_s`` to ``t_s`` with a body velocity and a yaw rate held over it.

    ``held_from_s`` is when the velocity sample started to be held (its DVL time, or the start
    of the integration if later): the step's share of the sample's error grows with it.
    ``var_yaw_gap_rad2``: the heading variance an AHRS gap adds over the step (rad^2).
    ``from_gyro``: the yaw rate is the gyro's (its bias then enters, :attr:`MotionStep.gyro_dt_s`).
    ``lever_arm_m``: the DVL's ``(x_m, y_m)`` when ``v_b_mps`` was compensated with this step's
    yaw rate (:func:`body_velocity`): with the gyro's, the bias enters the displacement too
    (:attr:`MotionStep.dx_dbias_m_s`).
    """
    dt = max(t_s - t_prev_s, 0.0)
    v = np.asarray(v_b_mps, dtype=np.float64)
    gyro_dt = dt if from_gyro else 0.0
    return MotionStep(
        t_s=float(t_s),
        dt_s=dt,
        dx_m=dt * float(v[0]),
        dy_m=dt * float(v[1]),
        dyaw_rad=dt * float(yaw_rate_rad_per_s),
        sigma_v_mps=float(sigma_v_mps),
        held_s=max(t_s - held_from_s, dt),
        var_yaw_gap_rad2=float(var_yaw_gap_rad2),
        gyro_dt_s=gyro_dt,
        dx_dbias_m_s=-gyro_dt * lever_arm_m[1],
        dy_dbias_m_s=gyro_dt * lever_arm_m[0],
    )


def step_displacement(yaw_rad: float, dx_b_m: float, dy_b_m: float) -> tuple[float, float]:
    """The step in the world ``R(yaw) (dx_b, dy_b)`` (m): the translation of the motion model.

    Plain floats: it runs for every record in every estimator.
    """
    c, s = math.cos(yaw_rad), math.sin(yaw_rad)
    return c * dx_b_m - s * dy_b_m, s * dx_b_m + c * dy_b_m


class RelativeMotion:
    """Motion since a start, ``(x, y, yaw)`` in the start's body frame, and its covariance.

    The motion model from the identity, in plain floats: ``P <- F P F^T + diag(qv, qv, qr)``.
    It also carries the gyro's own integral and ``d(x, y) / d(gyro scale)`` for the factor
    graph's gyro-scale odometry (:func:`sonarslam.slam.backends.isam2.factors.odometry_residual`).
    """

    __slots__ = ("x", "y", "yaw", "a", "b", "c", "d", "e", "f", "yaw_raw", "jx", "jy")

    def __init__(self) -> None:
        self.reset()

    def reset(self) -> None:
        self.x = self.y = self.yaw = 0.0
        self.a = self.b = self.c = self.d = self.e = self.f = 0.0  # Pxx Pxy Pyy Pxyaw Pyyaw Pyaw
        self.yaw_raw = self.jx = self.jy = 0.0  # the gyro's own integral, d(x, y)/d(scale)

    def step(
        self, sx: float, sy: float, syaw: float, qv: float, qr: float, syaw_raw: float = 0.0
    ) -> None:
        """One step: body displacement ``(sx, sy)``, yaw change ``syaw`` (``syaw_raw`` before
        the gyro scale), velocity and yaw variances ``qv``, ``qr``."""
        dx, dy = step_displacement(self.yaw, sx, sy)
        # the step's direction turns with the scale through the yaw so far: d/ds = S d yaw_raw
        self.jx -= dy * self.yaw_raw
        self.jy += dx * self.yaw_raw
        self.yaw_raw += syaw_raw
        a, b, cc, d, e, f = self.a, self.b, self.c, self.d, self.e, self.f
        self.a = a - 2.0 * dy * d + dy * dy * f + qv
        self.b = b - dy * e + dx * d - dx * dy * f
        self.c = cc + 2.0 * dx * e + dx * dx * f + qv
        self.d = d - dy * f
        self.e = e + dx * f
        self.f = f + qr
        self.x += dx
        self.y += dy
        self.yaw += syaw

    def copy_from(self, other: RelativeMotion, rotate_rad: float = 0.0, gain: float = 1.0) -> None:
        """Take another motion, its translation rotated by ``rotate_rad`` (the misalignment) and
        scaled by ``gain`` (the DVL's scale, ``1 + k``); the covariance alike."""
        c, s = gain * math.cos(rotate_rad), gain * math.sin(rotate_rad)
        self.x, self.y = c * other.x - s * other.y, s * other.x + c * other.y
        self.yaw = other.yaw
        a, b, cc, d, e = other.a, other.b, other.c, other.d, other.e
        # [x y] <- M [x y] with M = [[c, -s], [s, c]]: M P M^T and M p_xy,yaw
        self.a = c * c * a - 2.0 * c * s * b + s * s * cc
        self.b = c * s * (a - cc) + (c * c - s * s) * b
        self.c = s * s * a + 2.0 * c * s * b + c * c * cc
        self.d, self.e, self.f = c * d - s * e, s * d + c * e, other.f
        self.yaw_raw, self.jx, self.jy = other.yaw_raw, other.jx, other.jy

    @property
    def pose(self) -> FloatArray:
        return np.array([self.x, self.y, self.yaw])

    @property
    def cov(self) -> FloatArray:
        """Covariance of ``(x, y, yaw)`` (m, m, rad)."""
        return np.array(
            [[self.a, self.b, self.d], [self.b, self.c, self.e], [self.d, self.e, self.f]]
        )


class OdometryChain:
    """The odometry ``O(t)``: the relative motions of a run chained in their own frame.

    ``(x_m, y_m, yaw_rad)`` at every step's time with the yaw unwrapped, and the position
    variance per axis accumulated from the velocity noise (isotropic, so frame-free). Growing
    contiguous buffers (amortised doubling); a query searches the times and interpolates only
    over the steps spanning it (a sector of beams), so it costs the same at the end of a long
    run as at its start.
    """

    def __init__(self, t0_s: float, capacity: int = 4096) -> None:
        cap = max(capacity, 1)
        self._t = np.empty(cap)
        self._odo = np.empty((cap, 3))  # x, y, unwrapped yaw
        self._var = np.empty(cap)
        self._t[0] = t0_s
        self._odo[0] = 0.0
        self._var[0] = 0.0
        self._n = 1
        self._x = self._y = self._yaw = self._v = 0.0

    def __len__(self) -> int:
        return self._n

    def append(self, t_s: float, bTb_next: FloatArray, var_step_m2: float = 0.0) -> None:
        """Chain one step of relative motion ``(dx_b, dy_b, dyaw)`` ending at ``t_s``."""
        if self._n == self._t.size:
            self._t = np.concatenate([self._t, np.empty_like(self._t)])
            self._odo = np.concatenate([self._odo, np.empty_like(self._odo)])
            self._var = np.concatenate([self._var, np.empty_like(self._var)])
        dx, dy = step_displacement(self._yaw, float(bTb_next[0]), float(bTb_next[1]))
        self._x += dx
        self._y += dy
        self._yaw += float(bTb_next[2])
        self._v += var_step_m2
        n = self._n
        self._t[n] = t_s
        self._odo[n] = (self._x, self._y, self._yaw)
        self._var[n] = self._v
        self._n += 1

    @property
    def t_s(self) -> FloatArray:
        """Times of the chain's steps (Unix s), shape (K,)."""
        return self._t[: self._n]

    @property
    def now(self) -> FloatArray:
        """The chain's newest ``(x_m, y_m, yaw_rad)``, yaw unwrapped."""
        return np.array([self._x, self._y, self._yaw])

    def _span(self, t_s: FloatArray) -> slice:
        """The steps that bracket the query times, never empty (steps may share a time)."""
        t = self._t[: self._n]
        lo = max(int(np.searchsorted(t, t_s.min(), side="left")) - 1, 0)
        hi = min(int(np.searchsorted(t, t_s.max(), side="right")) + 1, self._n)
        return slice(lo, hi)

    def at(self, t_s: npt.ArrayLike) -> FloatArray:
        """``O(t)`` interpolated linearly (held past the ends), shape (M, 3), yaw unwrapped."""
        tq = np.atleast_1d(np.asarray(t_s, dtype=np.float64))
        part = self._span(tq)
        t, odo = self._t[part], self._odo[part]
        return np.column_stack([np.interp(tq, t, odo[:, k]) for k in range(3)])

    def variance_at(self, t_s: float) -> float:
        """Accumulated position variance per axis at ``t_s`` (m^2), interpolated."""
        tq = np.array([t_s], dtype=np.float64)
        part = self._span(tq)
        return float(np.interp(t_s, self._t[part], self._var[part]))

    def variances_at(self, t_s: npt.ArrayLike) -> FloatArray:
        """:meth:`variance_at` of many times in one search, shape (M,) (m^2)."""
        tq = np.atleast_1d(np.asarray(t_s, dtype=np.float64))
        part = self._span(tq)
        return np.asarray(np.interp(tq, self._t[part], self._var[part]))


@dataclass(frozen=True)
class VelocityInput:
    """Body velocity held between DVL samples, with its 1-sigma, at given times."""

    v_b_mps: FloatArray  # (N, 2) body velocity (lever arm compensated with the given yaw rate)
    sigma_mps: FloatArray  # (N,)
    in_dropout: np.ndarray  # (N,) bool
    sample_t_s: FloatArray  # (N,) since when the velocity has been held (Unix s)
    v_dvl_mps: FloatArray  # (N, 2) the held velocity in the DVL frame (zero where none is)


def velocity_input(
    t_s: FloatArray,
    dvl: DvlSeries,
    dvl_mounting: Mounting,
    noise: MotionNoise,
    yaw_rate_rad_per_s: npt.ArrayLike = 0.0,
) -> VelocityInput:
    """Body velocity at times ``t_s``: the last valid DVL sample (zero-order hold).

    The held DVL velocity becomes the body velocity at each time by :func:`body_velocity` with
    ``yaw_rate_rad_per_s`` (scalar or shape (N,), the yaw rate the model turns by from that time
    on, :func:`yaw_rate_input`); a caller that knows the rate only step by step (the closed
    loop) gives none and converts :attr:`VelocityInput.v_dvl_mps` itself.
    The 1-sigma of a valid sample is :func:`sonarslam.slam.model.noise.dvl_sample_sigma`. During a
    dropout (the newest DVL row has no bottom lock, or the newest valid sample is older than
    ``dvl_stale_s``: a gap of the DVL) the last valid velocity is held and its 1-sigma grows
    linearly from that to ``gap_sigma_mps`` (or stays, when larger) over ``dvl_max_gap_s``;
    past that the velocity is zero with ``gap_sigma_mps``, held since the dropout expired.
    Before the first valid sample it is zero, held since the query time. Those zeros are the
    DVL's (its point at rest), converted like any sample.

    Raises
    ------
    DataError
        No DVL row has bottom lock: there is no velocity to navigate with (an AHRS-only mode
        would stand still with a growing covariance; a clear error is more use).
    """
    if not dvl.valid.any():
        raise DataError(
            dvl.path or "DVL",
            None,
            f"none of its {dvl.t.size} rows has a valid bottom lock (or a plausible speed):"
            " no velocity to navigate with",
        )
    valid_t = dvl.t[dvl.valid]
    v_dvl_valid = np.asarray(dvl.v_mps[dvl.valid], dtype=np.float64)
    # the sample noise from the DVL's own scatter, in body axes (no lever arm: its wobble)
    sigma_valid = dvl_sample_sigma(valid_t, body_velocity(v_dvl_valid, dvl_mounting), noise)
    last_valid = np.searchsorted(valid_t, t_s, side="right") - 1
    last_any = np.searchsorted(dvl.t, t_s, side="right") - 1
    have = last_valid >= 0
    v = np.where(have[:, None], v_dvl_valid[np.clip(last_valid, 0, None)], 0.0)
    age = np.where(have, t_s - valid_t[np.clip(last_valid, 0, None)], np.inf)
    # In dropout when the newest DVL row at t is an invalid one, or the sample is stale (a gap).
    newest_invalid = (last_any >= 0) & ~dvl.valid[np.clip(last_any, 0, None)]
    in_dropout = newest_invalid | ~have | (age > noise.dvl_stale_s)
    frac = np.clip(np.where(in_dropout, age, 0.0) / noise.dvl_max_gap_s, 0.0, 1.0)
    s0 = np.where(have, sigma_valid[np.clip(last_valid, 0, None)], noise.dvl_sigma_mps)
    sigma = np.maximum(s0 + frac * (noise.gap_sigma_mps - s0), s0)
    expired = in_dropout & (age > noise.dvl_max_gap_s)
    v[expired] = 0.0
    sigma = np.where(expired, noise.gap_sigma_mps, sigma)
    sample_t = np.where(have, t_s - np.where(np.isfinite(age), age, 0.0), t_s)
    sample_t = np.where(expired & have, sample_t + noise.dvl_max_gap_s, sample_t)
    v_b = body_velocity(v, dvl_mounting, yaw_rate_rad_per_s)
    return VelocityInput(
        v_b_mps=v_b, sigma_mps=sigma, in_dropout=in_dropout, sample_t_s=sample_t, v_dvl_mps=v
    )


def gyro_bias_against_heading(
    attitude: AttitudeSeries, window_s: float = 10.0
) -> tuple[float, float]:
    """The gyro's yaw-rate bias measured against the AHRS heading's own change, GPS-free:
    over windows of ``window_s``, the gyro's integral minus the heading's change (unwrapped)
    per second; their median and its standard error (from the median absolute deviation),
    rad/s. A window's heading noise enters once, not at every sample. ``(0, inf)`` with fewer
    than 5 windows (docs/research/calibration.md gives the marina MTi's)."""
    t = attitude.t
    if t.size < 2:
        return 0.0, float("inf")
    yaw = np.unwrap(attitude.yaw_rad)
    turned = np.concatenate([[0.0], np.cumsum(attitude.yaw_rate_rad_per_s[:-1] * np.diff(t))])
    w = np.floor((t - t[0]) / window_s).astype(np.int64)
    first = np.flatnonzero(np.diff(w, prepend=-1))  # the first sample of each window
    last = np.append(first[1:] - 1, t.size - 1)
    span = t[last] - t[first]
    ok = span > 0.5 * window_s
    if int(ok.sum()) < 5:
        return 0.0, float("inf")
    d = ((turned[last] - turned[first]) - (yaw[last] - yaw[first]))[ok] / span[ok]
    bias = float(np.median(d))
    sd = 1.4826 * float(np.median(np.abs(d - bias)))
    return bias, 1.2533 * sd / math.sqrt(d.size)  # the median's standard error


def dead_reckoning(
    attitude: AttitudeSeries,
    dvl: DvlSeries,
    dvl_mounting: Mounting,
    ahrs_mounting: Mounting,
    start_wTb: npt.ArrayLike,
    start_cov: npt.ArrayLike,
    t0_s: float,
    t1_s: float,
    noise: MotionNoise,
    ahrs_deviation_rad: tuple[float, float] = (0.0, 0.0),
    yaw_rate_source: str = "gyro",
) -> Trajectory:
    """Dead reckoning from DVL velocity and AHRS heading on the AHRS timeline (10 Hz marina).

    Position integrates ``R(psi_b) v_b`` with the velocity held from the last DVL sample
    (:func:`velocity_input`), its lever arm compensated with the yaw rate of
    ``yaw_rate_source`` (:func:`yaw_rate_input`, as the closed loop turns); heading is the AHRS heading (absolute, not integrated), so the
    position covariance grows and the heading variance stays ``ahrs_sigma_rad**2``. The start
    position is ``start_wTb[:2]`` at ``t0_s`` (the first GPS fix by the ATE protocol); the start
    yaw is the AHRS's.

    Returns
    -------
    Trajectory
        Poses and covariances at ``t0_s`` and every AHRS sample in ``(t0_s, t1_s]``.
    """
    inside = (attitude.t > t0_s) & (attitude.t <= t1_s)
    t_ahrs = np.concatenate([[t0_s], attitude.t[inside]])
    t = _with_gap_times(t_ahrs, dvl.t, noise.ahrs_stale_s)
    yaw_unwrapped = np.unwrap(attitude.yaw_rad)
    yaw = np.interp(t, attitude.t, yaw_unwrapped)
    # in an AHRS gap (the added times) the last sample's heading is held, causally, with a
    # variance that grows with the time it has been stale
    last = np.clip(np.searchsorted(attitude.t, t, side="right") - 1, 0, None)
    age = np.where(np.isin(t, t_ahrs), 0.0, t - attitude.t[last])
    yaw = np.where(age > 0.0, yaw_unwrapped[last], yaw)
    psi = body_yaw(yaw, ahrs_mounting, ahrs_deviation_rad)
    var_heading = noise.ahrs_sigma_rad**2 + noise.gap_heading_variance(age - noise.ahrs_stale_s)
    rate = yaw_rate_input(
        t, attitude, ahrs_mounting, yaw_rate_source, noise.ahrs_stale_s, ahrs_deviation_rad
    )
    vin = velocity_input(t, dvl, dvl_mounting, noise, rate)
    dt = np.diff(t)
    # the steps in the world: R(psi) (dt v_b), the model's translation, all at once
    heading = np.column_stack([np.zeros((dt.size, 2)), psi[:-1]])
    d_w = transform_points(heading, vin.v_b_mps[:-1] * dt[:, None])
    start = np.asarray(start_wTb, dtype=np.float64)
    xy = start[:2] + np.vstack([[0.0, 0.0], np.cumsum(d_w, axis=0)])

    # Covariance of the position increments: velocity noise (isotropic, so R Sigma R^T = Sigma),
    # counted once per held DVL sample, and heading noise through d(R v)/d psi = (-dy_w, dx_w).
    held = np.maximum(t[1:] - np.maximum(vin.sample_t_s[:-1], t0_s), dt)
    var_v = held_velocity_variance_step(held, dt, vin.sigma_mps[:-1])
    jx, jy = -d_w[:, 1], d_w[:, 0]
    var_h = var_heading[:-1]
    q = np.zeros((dt.size, 2, 2))
    q[:, 0, 0] = var_v + var_h * jx * jx
    q[:, 1, 1] = var_v + var_h * jy * jy
    q[:, 0, 1] = q[:, 1, 0] = var_h * jx * jy
    covs = np.zeros((t.size, 3, 3))
    covs[:, :2, :2] = np.asarray(start_cov, dtype=np.float64)[:2, :2] + np.concatenate(
        [np.zeros((1, 2, 2)), np.cumsum(q, axis=0)]
    )
    covs[:, 2, 2] = var_heading
    return Trajectory(t, np.column_stack([xy, psi]), covs)


def _with_gap_times(t_ahrs_s: FloatArray, t_dvl_s: FloatArray, stale_s: float) -> FloatArray:
    """``t_ahrs_s`` (increasing) with the DVL times that fall inside its gaps (two samples
    more than ``stale_s`` apart), so that dead reckoning steps through a silent AHRS at the
    DVL's pace instead of in one long step."""
    if not np.isfinite(stale_s) or t_ahrs_s.size < 2:
        return t_ahrs_s
    j = np.searchsorted(t_ahrs_s, t_dvl_s, side="right") - 1
    inside = (j >= 0) & (j < t_ahrs_s.size - 1)
    jj = np.clip(j, 0, t_ahrs_s.size - 2)
    in_gap = inside & (t_ahrs_s[jj + 1] - t_ahrs_s[jj] > stale_s) & (t_dvl_s > t_ahrs_s[jj])
    return np.union1d(t_ahrs_s, t_dvl_s[in_gap])
