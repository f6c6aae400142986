"""Motion model from DVL body velocity and AHRS heading, and dead reckoning with its covariance.

Frames: the DVL measures velocity in its own frame; ``v_b = R(dvl_yaw) v_dvl`` in the body frame
(x forward, y left). The AHRS gives the yaw of its own frame; the body yaw is
``psi_b = psi_ahrs - ahrs_yaw`` (mountings in :mod:`datasets.config`). Lever arms are ignored
(the vehicle turns slowly; a 0.3 m arm at 5 deg/s is 2.6 cm/s, below the DVL noise).

The same :func:`propagate` is the prediction of the EKF and the odometry of the factor graph.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from datasets.marina import AttitudeSeries, DvlSeries
from features.geometry import FloatArray, wrap_angle
from slam.io.trajectory import Trajectory
from sonar.beam import Mounting

__all__ = [
    "MotionNoise",
    "body_velocity",
    "body_yaw",
    "held_velocity_variance_step",
    "dvl_scatter",
    "dvl_sample_sigma",
    "propagate",
    "VelocityInput",
    "velocity_input",
    "dead_reckoning",
]


@dataclass(frozen=True)
class MotionNoise:
    """Noise of the motion model.

    Attributes
    ----------
    dvl_sigma_mps : float
        1-sigma of a valid DVL velocity, per axis (m/s).
    ahrs_sigma_rad : float
        1-sigma of the AHRS heading (rad).
    dvl_max_gap_s : float
        A DVL dropout up to this long holds the last valid velocity; longer, the velocity is
        taken as zero with ``gap_sigma_mps``.
    gap_sigma_mps : float
        Velocity 1-sigma added during a dropout (grows linearly to this at ``dvl_max_gap_s``).
    dvl_scatter_window_s : float
        Window (s) of the DVL's own scatter (:func:`dvl_scatter`); 0 turns the excess-scatter
        noise off.
    dvl_nominal_scatter_mps : float
        The scatter of the DVL when it works as usual (m/s): its excess over this is white
        velocity noise added to ``dvl_sigma_mps`` (:func:`dvl_sample_sigma`).
    """

    dvl_sigma_mps: float = 0.05
    ahrs_sigma_rad: float = float(np.deg2rad(2.0))
    dvl_max_gap_s: float = 10.0
    gap_sigma_mps: float = 0.3
    dvl_scatter_window_s: float = 0.0
    dvl_nominal_scatter_mps: float = 0.0


def body_velocity(v_dvl_mps: npt.ArrayLike, dvl_mounting: Mounting) -> FloatArray:
    """DVL-frame velocities (N, 2) to body-frame velocities (N, 2) (m/s)."""
    v = np.atleast_2d(np.asarray(v_dvl_mps, dtype=np.float64))
    c, s = np.cos(dvl_mounting.yaw_rad), np.sin(dvl_mounting.yaw_rad)
    return np.column_stack([c * v[:, 0] - s * v[:, 1], s * v[:, 0] + c * v[:, 1]])


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


def held_velocity_variance_step(
    held_s: npt.ArrayLike, dt_s: npt.ArrayLike, sigma_mps: npt.ArrayLike
) -> FloatArray:
    """Position variance (m^2, per axis) added by one step while one DVL sample is held.

    The error of a held velocity sample is the same at every step of the hold, so the position
    error over a hold of ``T`` seconds is ``T * sigma`` (variance ``T^2 sigma^2``), not
    ``sqrt(sum dt^2) * sigma``. A step of ``dt`` that ends ``held_s`` after the sample adds
    ``(held_s^2 - (held_s - dt)^2) sigma^2 = (2 held_s - dt) dt sigma^2``.
    """
    T = np.asarray(held_s, dtype=np.float64)
    dt = np.asarray(dt_s, dtype=np.float64)
    return np.asarray((2.0 * T - dt) * dt * np.asarray(sigma_mps, dtype=np.float64) ** 2)


def propagate(
    wTb: npt.ArrayLike, v_b_mps: npt.ArrayLike, yaw_rate_radps: float, dt_s: float
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """One step of the constant-velocity model ``x += dt R(psi) v_b``, ``psi += dt r``.

    Returns
    -------
    wTb_next : ndarray, shape (3,)
    F : ndarray, shape (3, 3)
        Jacobian with respect to the pose.
    G : ndarray, shape (3, 3)
        Jacobian with respect to the inputs ``(v_x, v_y, r)``.
    """
    x, y, psi = (float(v) for v in np.asarray(wTb, dtype=np.float64))
    vx, vy = (float(v) for v in np.asarray(v_b_mps, dtype=np.float64))
    c, s = np.cos(psi), np.sin(psi)
    dx, dy = dt_s * (c * vx - s * vy), dt_s * (s * vx + c * vy)
    nxt = np.array([x + dx, y + dy, float(wrap_angle(psi + dt_s * yaw_rate_radps))])
    F = np.array([[1.0, 0.0, -dy], [0.0, 1.0, dx], [0.0, 0.0, 1.0]])
    G = np.array([[dt_s * c, -dt_s * s, 0.0], [dt_s * s, dt_s * c, 0.0], [0.0, 0.0, dt_s]])
    return nxt, F, G


def dvl_scatter(t_s: FloatArray, v_mps: FloatArray, window_s: float) -> FloatArray:
    """Causal scatter of DVL velocities (m/s, per axis) at each sample: the root mean square of
    ``|v_k - v_{k-1}| / 2`` over the samples of the last ``window_s`` seconds.

    For white noise of 1-sigma ``s`` per axis, ``E |v_k - v_{k-1}|^2 = 4 s^2``, so this
    estimates ``s`` (the Allan deviation at one sample); the vehicle's own accelerations add
    little at ~1 Hz. The first sample has no difference and takes the second's value.

    Parameters
    ----------
    t_s : ndarray, shape (N,)
        Times of the valid samples (s), increasing.
    v_mps : ndarray, shape (N, 2)
        Their velocities (m/s).
    window_s : float
        Averaging window (s), > 0.

    Returns
    -------
    ndarray, shape (N,)
    """
    n = t_s.size
    if n < 2:
        return np.zeros(n)
    d2 = np.concatenate([[np.nan], 0.25 * np.sum(np.diff(v_mps, axis=0) ** 2, axis=1)])
    d2[0] = d2[1]
    csum = np.concatenate([[0.0], np.cumsum(d2)])
    first = np.searchsorted(t_s, t_s - window_s, side="right")
    count = np.arange(1, n + 1) - first
    return np.asarray(np.sqrt((csum[1:] - csum[first]) / count))


def dvl_sample_sigma(t_s: FloatArray, v_mps: FloatArray, noise: MotionNoise) -> FloatArray:
    """1-sigma (m/s, per axis) of each valid DVL sample: ``dvl_sigma_mps``, plus the excess of
    the DVL's own scatter over its nominal scatter taken as white noise,
    ``sqrt(dvl_sigma^2 + max(0, scatter^2 - nominal^2))``.

    ``dvl_sigma_mps`` is the error that accumulates into drift when the DVL works as usual; its
    scatter then is mostly the vehicle's real wobble, which integrates to nothing. When the
    scatter rises above that (the marina's last ~700 s, bottom at 1.3 m: 0.35 against
    0.15 m/s, white up to a minute), the excess does integrate, and the estimators must know.
    """
    base = np.full(t_s.size, noise.dvl_sigma_mps)
    if noise.dvl_scatter_window_s <= 0.0:
        return base
    s = dvl_scatter(t_s, v_mps, noise.dvl_scatter_window_s)
    excess = np.maximum(s**2 - noise.dvl_nominal_scatter_mps**2, 0.0)
    return np.asarray(np.sqrt(base**2 + excess))


@dataclass(frozen=True)
class VelocityInput:
    """Body velocity held between DVL samples, with its 1-sigma, at given times."""

    v_b_mps: FloatArray  # (N, 2)
    sigma_mps: FloatArray  # (N,)
    in_dropout: np.ndarray  # (N,) bool
    sample_t_s: FloatArray  # (N,) time of the held DVL sample (Unix s); the query time if none


def velocity_input(
    t_s: FloatArray, dvl: DvlSeries, dvl_mounting: Mounting, noise: MotionNoise
) -> VelocityInput:
    """Body velocity at times ``t_s``: the last valid DVL sample (zero-order hold).

    The 1-sigma of a valid sample is :func:`dvl_sample_sigma`. During a bottom-lock dropout the
    last valid velocity is held and its 1-sigma grows linearly from that to ``gap_sigma_mps``
    (or stays, when larger) over ``dvl_max_gap_s``; past that the velocity is zero with
    ``gap_sigma_mps``. Before the first valid sample it is zero.
    """
    valid_t = dvl.t[dvl.valid]
    v_valid = body_velocity(dvl.v_mps[dvl.valid], dvl_mounting)
    sigma_valid = dvl_sample_sigma(valid_t, v_valid, noise)
    last_valid = np.searchsorted(valid_t, t_s, side="right") - 1
    last_any = np.searchsorted(dvl.t, t_s, side="right") - 1
    have = last_valid >= 0
    v = np.where(have[:, None], v_valid[np.clip(last_valid, 0, None)], 0.0)
    age = np.where(have, t_s - valid_t[np.clip(last_valid, 0, None)], np.inf)
    # In dropout when the newest DVL row at t is an invalid one.
    newest_invalid = (last_any >= 0) & ~dvl.valid[np.clip(last_any, 0, None)]
    in_dropout = newest_invalid | ~have
    frac = np.clip(np.where(in_dropout, age, 0.0) / noise.dvl_max_gap_s, 0.0, 1.0)
    s0 = np.where(have, sigma_valid[np.clip(last_valid, 0, None)], noise.dvl_sigma_mps)
    sigma = np.maximum(s0 + frac * (noise.gap_sigma_mps - s0), s0)
    expired = in_dropout & (age > noise.dvl_max_gap_s)
    v[expired] = 0.0
    sigma = np.where(expired, noise.gap_sigma_mps, sigma)
    sample_t = np.where(have & ~expired, t_s - np.where(np.isfinite(age), age, 0.0), t_s)
    return VelocityInput(v_b_mps=v, sigma_mps=sigma, in_dropout=in_dropout, sample_t_s=sample_t)


def dead_reckoning(
    attitude: AttitudeSeries,
    dvl: DvlSeries,
    dvl_mounting: Mounting,
    ahrs_mounting: Mounting,
    start_wTb: npt.ArrayLike,
    start_cov: npt.ArrayLike,
    t0_s: float,
    t1_s: float,
    noise: MotionNoise | None = None,
    ahrs_deviation_rad: tuple[float, float] = (0.0, 0.0),
) -> Trajectory:
    """Dead reckoning from DVL velocity and AHRS heading on the AHRS timeline (10 Hz marina).

    Position integrates ``R(psi_b) v_b`` with the velocity held from the last DVL sample
    (:func:`velocity_input`); heading is the AHRS heading (absolute, not integrated), so the
    position covariance grows and the heading variance stays ``ahrs_sigma_rad**2``. The start
    position is ``start_wTb[:2]`` at ``t0_s`` (the first GPS fix by the ATE protocol); the start
    yaw is the AHRS's.

    Returns
    -------
    Trajectory
        Poses and covariances at ``t0_s`` and every AHRS sample in ``(t0_s, t1_s]``.
    """
    noise = noise or MotionNoise()
    inside = (attitude.t > t0_s) & (attitude.t <= t1_s)
    t = np.concatenate([[t0_s], attitude.t[inside]])
    yaw_unwrapped = np.unwrap(attitude.yaw_rad)
    psi = body_yaw(np.interp(t, attitude.t, yaw_unwrapped), ahrs_mounting, ahrs_deviation_rad)
    vin = velocity_input(t, dvl, dvl_mounting, noise)
    dt = np.diff(t)
    c, s = np.cos(psi[:-1]), np.sin(psi[:-1])
    v = vin.v_b_mps[:-1]
    vw = np.column_stack([c * v[:, 0] - s * v[:, 1], s * v[:, 0] + c * v[:, 1]])
    start = np.asarray(start_wTb, dtype=np.float64)
    xy = start[:2] + np.vstack([[0.0, 0.0], np.cumsum(vw * dt[:, None], axis=0)])

    # Covariance of the position increments: velocity noise (isotropic, so R Sigma R^T = Sigma),
    # counted once per held DVL sample, and heading noise through d(R v)/d psi = (-vw_y, vw_x).
    held = np.maximum(t[1:] - vin.sample_t_s[:-1], dt)
    var_v = held_velocity_variance_step(held, dt, vin.sigma_mps[:-1])
    jx, jy = -vw[:, 1] * dt, vw[:, 0] * dt
    var_h = noise.ahrs_sigma_rad**2
    q = np.zeros((dt.size, 2, 2))
    q[:, 0, 0] = var_v + var_h * jx * jx
    q[:, 1, 1] = var_v + var_h * jy * jy
    q[:, 0, 1] = q[:, 1, 0] = var_h * jx * jy
    covs = np.zeros((t.size, 3, 3))
    covs[:, :2, :2] = np.asarray(start_cov, dtype=np.float64)[:2, :2] + np.concatenate(
        [np.zeros((1, 2, 2)), np.cumsum(q, axis=0)]
    )
    covs[:, 2, 2] = var_h
    return Trajectory(t, np.column_stack([xy, psi]), covs)
