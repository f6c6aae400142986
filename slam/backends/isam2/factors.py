"""GTSAM factors of the line back end: line landmark, AHRS heading with bias, DVL odometry.

Variables (keys from :mod:`gtsam.symbol_shorthand`):

* ``X(k)``: body pose ``wTb`` of node k, a ``gtsam.Pose2``. GTSAM perturbs it in its *local*
  (body-frame) tangent ``(dx_b, dy_b, dtheta)``: ``wTb.retract(xi) = wTb * Exp(xi)``, so a
  Jacobian in plain world coordinates ``(x, y, yaw)`` is multiplied by
  :func:`sonarslam.slam.model.lines.local_to_world` ``= blockdiag(R(yaw), 1)``.
* ``L(j)``: a world line ``(rho_m, theta_rad)``, a 2-vector (a GTSAM ``Vector``: what
  ``Values.insert`` makes of a numpy array, read with ``Values.atVector``). A vector space
  (retract is ``+``) is what a ``(rho, theta)`` pair needs near a solution: ``theta`` enters
  only through ``cos`` and ``sin``, so it needs no wrapping in the state, and a manifold such as
  ``Pose2``/``Rot2`` would add nothing but conversions. The stored pair is not kept normalised
  (the optimiser may leave ``rho < 0`` or ``theta`` outside ``[-pi, pi)``); the factor compares
  lines through :func:`sonarslam.slam.model.lines.line_residual`, which normalises and resolves the sign
  ambiguity; reports normalise.
* ``B(0)``: the constant AHRS heading bias (rad), a size-1 ``Vector``; the AHRS measures
  ``yaw + b`` (the model of :class:`sonarslam.slam.backends.ekf.LineEkf`).
* ``D(0)``: optional constant misalignment (rad) of the DVL velocity with the body heading: the
  vehicle moves along ``R(yaw + delta) v_b`` (as :class:`sonarslam.slam.backends.ekf.LineEkf`).
* ``G(0)``: optional constant scale of the gyro's yaw rate (the odometry's heading change is
  ``s`` times the gyro's integral).
* ``C(0)``: optional sonar mounting ``bTs`` ``(x_m, y_m, yaw_rad)``, a size-3 ``Vector`` shared by
  every line and scan observation; ``R(0)``: optional sonar range scale ``s`` (size 1): the
  models of :mod:`sonarslam.slam.model.calibration`.

Every factor here is a ``gtsam.CustomFactor`` around a plain function that returns the error and
its analytic Jacobians (``tests/test_factor_graph.py`` checks them against
``gtsam.utils.numerical_derivative`` on the manifold).
"""

from __future__ import annotations

from typing import Any

import gtsam
import numpy as np
import numpy.typing as npt

from sonarslam.features.geometry import FloatArray, wrap_angle
from sonarslam.features.line import LineFeature, check_mounting
from sonarslam.slam.model.calibration import line_residual_calibrated, scan_residual
from sonarslam.slam.model.lines import line_residual
from sonarslam.slam.model.noise import robust_kernel

__all__ = [
    "noise_model",
    "line_factor",
    "calibrated_line_factor",
    "calibrated_scan_factor",
    "line_equality_residual",
    "line_equality_factor",
    "heading_residual",
    "heading_factor",
    "odometry_residual",
    "odometry_factor",
    "mount_prior_dvl_residual",
    "mount_prior_dvl_factor",
]

_S = np.array([[0.0, -1.0], [1.0, 0.0]])  # d R(a) / da = R(a) S


def noise_model(
    cov: npt.ArrayLike, robust: str | None = None, robust_k: float = 1.345
) -> gtsam.noiseModel.Base:
    """A Gaussian noise model of covariance ``cov``, optionally wrapped in a robust kernel.

    Parameters
    ----------
    cov : array_like, shape (n, n)
        Covariance of the factor's error, in its units.
    robust : {None, "huber", "cauchy"}
        Robust kernel (:func:`sonarslam.slam.model.noise.robust_kernel`) on the whitened error.
    robust_k : float
        Kernel width in sigmas (Huber: 1.345 is 95 % efficient on Gaussian data).
    """
    base = gtsam.noiseModel.Gaussian.Covariance(np.asarray(cov, dtype=np.float64))
    kernel = robust_kernel(robust, robust_k)
    return base if kernel is None else gtsam.noiseModel.Robust.Create(kernel, base)


# -- line landmark -----------------------------------------------------------------------------


def line_factor(
    pose_key: int,
    line_key: int,
    z: LineFeature | npt.ArrayLike,
    cov: npt.ArrayLike | None = None,
    bTs: npt.ArrayLike | None = None,
    robust: str | None = None,
    robust_k: float = 1.345,
) -> gtsam.CustomFactor:
    """Factor between ``X(k)`` (Pose2 ``wTb``) and ``L(j)`` (2-vector ``(rho_w, theta_w)``).

    Parameters
    ----------
    pose_key, line_key : int
        Keys of the body pose and of the world line.
    z : LineFeature or array_like, shape (2,)
        The observation: a line of the extractor (its ``z``, ``cov`` and mounting ``bTs``), or
        the measured line ``(rho_m, theta_rad)`` in the sonar frame R, normalised.
    cov : array_like, shape (2, 2), optional
        Its covariance (the extractor's): required with an array ``z``; a line's own by default.
    bTs : array_like, shape (3,), optional
        Sonar mounting, a constant of the factor: required with an array ``z``; a line's own
        (:attr:`~sonarslam.features.line.LineFeature.bTs`) by default, and another than the
        line's is refused (ValueError naming it).
    robust, robust_k
        See :func:`noise_model`.
    """
    if isinstance(z, LineFeature):
        if bTs is None:
            if z.bTs is None:
                raise ValueError("line_factor: bTs is required for a line without its mounting")
            bTs = z.bTs
        check_mounting([z], bTs, "line_factor(bTs=...)")
        cov = z.cov if cov is None else cov
        z = z.z
    if cov is None or bTs is None:
        raise TypeError("line_factor: cov and bTs are required with a measured line z")
    z_m = np.asarray(z, dtype=np.float64).copy()
    bTs_m = np.asarray(bTs, dtype=np.float64).copy()

    def error(this: gtsam.CustomFactor, values: gtsam.Values, H: Any) -> FloatArray:
        keys = this.keys()
        p = values.atPose2(keys[0])
        wTb = np.array([p.x(), p.y(), p.theta()])
        e, H_pose, H_line = line_residual(z_m, wTb, values.atVector(keys[1]), bTs_m)
        if H is not None:
            H[0] = H_pose
            H[1] = H_line
        return e

    return gtsam.CustomFactor(noise_model(cov, robust, robust_k), [pose_key, line_key], error)


def _pose(values: gtsam.Values, key: int) -> FloatArray:
    p = values.atPose2(key)
    return np.array([p.x(), p.y(), p.theta()])


def calibrated_line_factor(
    pose_key: int,
    line_key: int,
    z: npt.ArrayLike,
    cov: npt.ArrayLike,
    kTb: npt.ArrayLike,
    bTs: npt.ArrayLike,
    mount_key: int | None = None,
    scale_key: int | None = None,
    robust: str | None = None,
    robust_k: float = 1.345,
) -> gtsam.CustomFactor:
    """A line observation on ``X(k)``, ``L(j)`` and the sonar's calibration: the mounting
    ``C(0)`` (or the constant ``bTs`` without ``mount_key``) and the range scale ``R(0)`` (or 1
    without ``scale_key``); error :func:`sonarslam.slam.model.calibration.line_residual_calibrated`.

    Parameters
    ----------
    z, cov
        The measured line in the sonar frame and its covariance.
    kTb : array_like, shape (3,)
        The body's pose at the observation in node ``k``'s frame (a constant).
    bTs : array_like, shape (3,)
        The mounting when it is not a variable.
    """
    z_m = np.asarray(z, dtype=np.float64).copy()
    kTb_m = np.asarray(kTb, dtype=np.float64).copy()
    bTs_m = np.asarray(bTs, dtype=np.float64).copy()
    keys, i_mount, i_scale = _with_calibration([pose_key, line_key], mount_key, scale_key)

    def error(this: gtsam.CustomFactor, values: gtsam.Values, H: Any) -> FloatArray:
        k = this.keys()
        mount, scale = _calibration(values, k, i_mount, i_scale, bTs_m)
        e, H_pose, H_line, H_mount, H_scale = line_residual_calibrated(
            z_m, _pose(values, k[0]), values.atVector(k[1]), kTb_m, mount, scale
        )
        if H is not None:
            H[0] = H_pose
            H[1] = H_line
            _set_calibration_jacobians(H, i_mount, i_scale, H_mount, H_scale)
        return e

    return gtsam.CustomFactor(noise_model(cov, robust, robust_k), keys, error)


def calibrated_scan_factor(
    key_i: int,
    key_j: int,
    z: npt.ArrayLike,
    cov: npt.ArrayLike,
    bTs_assumed: npt.ArrayLike,
    mount_key: int | None = None,
    scale_key: int | None = None,
    robust: str | None = None,
    robust_k: float = 1.0,
) -> gtsam.CustomFactor:
    """A scan registration ``z`` (``iTj`` of the body nodes, measured with the front end's
    mounting ``bTs_assumed``) on ``X(i)``, ``X(j)``, the mounting ``C(0)`` and the range scale
    ``R(0)`` (either may be absent: the assumed mounting, scale 1); error
    :func:`sonarslam.slam.model.calibration.scan_residual`, ``cov`` in ``z``'s local tangent."""
    z_m = np.asarray(z, dtype=np.float64).copy()
    a = np.asarray(bTs_assumed, dtype=np.float64).copy()
    keys, i_mount, i_scale = _with_calibration([key_i, key_j], mount_key, scale_key)

    def error(this: gtsam.CustomFactor, values: gtsam.Values, H: Any) -> FloatArray:
        k = this.keys()
        mount, scale = _calibration(values, k, i_mount, i_scale, a)
        e, H_i, H_j, H_mount, H_scale = scan_residual(
            z_m, _pose(values, k[0]), _pose(values, k[1]), mount, scale, a
        )
        if H is not None:
            H[0] = H_i
            H[1] = H_j
            _set_calibration_jacobians(H, i_mount, i_scale, H_mount, H_scale)
        return e

    return gtsam.CustomFactor(noise_model(cov, robust, robust_k), keys, error)


def line_equality_residual(
    line_keep: FloatArray, line_drop: FloatArray, flipped: bool
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """The difference of two landmarks found to be one wall: ``line_drop`` in the
    representation chosen when they were merged (``(-rho, theta + pi)`` when ``flipped``) minus
    ``line_keep``, the angle wrapped.

    Returns
    -------
    e : ndarray, shape (2,)
    H_keep, H_drop : ndarray, shape (2, 2)
    """
    s = -1.0 if flipped else 1.0
    e = np.array(
        [
            s * line_drop[0] - line_keep[0],
            float(wrap_angle(line_drop[1] + (np.pi if flipped else 0.0) - line_keep[1])),
        ]
    )
    return e, -np.eye(2), np.diag([s, 1.0])


def line_equality_factor(
    keep_key: int, drop_key: int, flipped: bool, sigmas: npt.ArrayLike
) -> gtsam.CustomFactor:
    """Factor tying ``L(drop)`` to ``L(keep)`` (:func:`line_equality_residual`) with standard
    deviations ``sigmas`` ``(m, rad)``."""
    flip = bool(flipped)

    def error(this: gtsam.CustomFactor, values: gtsam.Values, H: Any) -> FloatArray:
        keys = this.keys()
        e, H_keep, H_drop = line_equality_residual(
            values.atVector(keys[0]), values.atVector(keys[1]), flip
        )
        if H is not None:
            H[0] = H_keep
            H[1] = H_drop
        return e

    noise = gtsam.noiseModel.Diagonal.Sigmas(np.asarray(sigmas, dtype=np.float64))
    return gtsam.CustomFactor(noise, [keep_key, drop_key], error)


# -- AHRS heading with a constant bias --------------------------------------------------------


def heading_residual(yaw_meas_rad: float, yaw_rad: float, bias_rad: float) -> float:
    """``wrap(yaw + b - z)``; its Jacobians are 1 for the pose's local ``dtheta`` and for ``b``."""
    return float(wrap_angle(yaw_rad + bias_rad - yaw_meas_rad))


_H_HEADING_POSE = np.array([[0.0, 0.0, 1.0]])
_H_HEADING_BIAS = np.array([[1.0]])


def heading_factor(
    pose_key: int, bias_key: int, yaw_meas_rad: float, sigma_rad: float
) -> gtsam.CustomFactor:
    """AHRS heading ``z = yaw(X(k)) + b``, with ``b = B(0)`` a size-1 Vector.

    Parameters
    ----------
    pose_key, bias_key : int
    yaw_meas_rad : float
        Body heading from the AHRS through its mounting (rad).
    sigma_rad : float
        White noise of one heading (rad).
    """
    z = float(yaw_meas_rad)

    def error(this: gtsam.CustomFactor, values: gtsam.Values, H: Any) -> FloatArray:
        keys = this.keys()
        e = heading_residual(z, values.atPose2(keys[0]).theta(), values.atVector(keys[1])[0])
        if H is not None:
            H[0] = _H_HEADING_POSE
            H[1] = _H_HEADING_BIAS
        return np.array([e])

    return gtsam.CustomFactor(
        gtsam.noiseModel.Isotropic.Sigma(1, float(sigma_rad)), [pose_key, bias_key], error
    )


# -- the sonar mounting's prior with its yaw relative to the DVL's track ---------------------------


def mount_prior_dvl_residual(
    z: FloatArray, mount: FloatArray, delta_rad: float
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Error of a prior on the sonar mounting ``C(0)`` whose yaw was calibrated relative to the
    DVL's track: ``(x - z_x, y - z_y, wrap(yaw - delta - z_yaw))`` with ``delta`` the DVL
    misalignment ``D(0)``.

    Rotating the mounting's yaw and the misalignment together turns the track and the map
    together and leaves the AHRS headings alone, so the data see only ``yaw - delta``; a yaw
    calibrated with dead-reckoning poses (``sonarslam calibrate --poses dr``, which holds
    ``delta = 0``) measured that difference, and its prior belongs on it.

    Returns
    -------
    e : ndarray, shape (3,)
    H_mount : ndarray, shape (3, 3)
        ``d e / d C(0)`` (the identity).
    H_delta : ndarray, shape (3, 1)
        ``d e / d D(0)``.
    """
    m = np.asarray(mount, dtype=np.float64)
    e = np.array([m[0] - z[0], m[1] - z[1], float(wrap_angle(m[2] - float(delta_rad) - z[2]))])
    return e, np.eye(3), np.array([[0.0], [0.0], [-1.0]])


def mount_prior_dvl_factor(
    mount_key: int, delta_key: int, z: npt.ArrayLike, cov: npt.ArrayLike
) -> gtsam.CustomFactor:
    """The prior of :func:`mount_prior_dvl_residual` on ``C(0)`` and ``D(0)``: ``z`` (3,) the
    calibrated mounting ``(x_m, y_m, yaw_rad)``, ``cov`` (3, 3) its covariance."""
    zz = np.asarray(z, dtype=np.float64).reshape(3)

    def error(this: gtsam.CustomFactor, values: gtsam.Values, H: Any) -> FloatArray:
        keys = this.keys()
        e, h_m, h_d = mount_prior_dvl_residual(
            zz, values.atVector(keys[0]), float(values.atVector(keys[1])[0])
        )
        if H is not None:
            H[0] = h_m
            H[1] = h_d
        return e

    return gtsam.CustomFactor(noise_model(cov), [mount_key, delta_key], error)


# -- DVL + gyro odometry with a misalignment and a gyro scale ------------------------------------


def odometry_residual(
    measured: FloatArray,
    wTi: FloatArray,
    wTj: FloatArray,
    delta_rad: float = 0.0,
    scale: float | None = None,
    yaw_raw_rad: float = 0.0,
    d_t_d_scale: FloatArray | None = None,
    scale0: float = 1.0,
    dvl_scale: float = 0.0,
) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray, FloatArray, FloatArray]:
    """Error of a relative motion integrated with a DVL misalignment, a gyro scale and a DVL
    scale-factor error ``k``.

    The motion model integrates ``R(yaw + delta) v_b`` with ``yaw`` the gyro's integral times
    its scale ``s``. Between two nodes, integrated with ``delta = 0`` and ``s = s0``, it gives
    ``measured = (t, yaw)``; for other values, to first order in ``s - s0``, the translation is
    ``(1 + k) R(delta) (t + (s - s0) dt/ds)`` and the heading change ``s * yaw_raw`` (``yaw_raw`` the
    gyro's own integral). With ``m`` that motion and ``r = wTi^-1 wTj`` the error is ``m^-1 r``
    in ``(x, y, yaw)``: ``(R(yaw_m)^T (r_t - m_t), wrap(r_yaw - yaw_m))``, the first-order
    equivalent of ``BetweenFactorPose2``'s. ``scale=None``: no scale, ``m_yaw = measured[2]``.

    Returns
    -------
    e : ndarray, shape (3,)
    H_i, H_j : ndarray, shape (3, 3)
        Jacobians in the local tangents of ``wTi`` and ``wTj``.
    H_delta, H_scale, H_k : ndarray, shape (3, 1)
    """
    ci, si = np.cos(wTi[2]), np.sin(wTi[2])
    Ri = np.array([[ci, -si], [si, ci]])
    r_t = Ri.T @ (wTj[:2] - wTi[:2])
    r_yaw = float(wrap_angle(wTj[2] - wTi[2]))
    q = np.array(measured[:2], dtype=np.float64)
    yaw_m = float(measured[2])
    J = np.zeros(2) if d_t_d_scale is None else np.asarray(d_t_d_scale, dtype=np.float64)
    if scale is not None:
        q = q + (scale - scale0) * J
        yaw_m = scale * yaw_raw_rad
    gain = 1.0 + dvl_scale
    cd, sd = np.cos(delta_rad), np.sin(delta_rad)
    Rd = np.array([[cd, -sd], [sd, cd]])
    m_t = gain * (Rd @ q)
    cm, sm = np.cos(yaw_m), np.sin(yaw_m)
    RmT = np.array([[cm, sm], [-sm, cm]])
    e = np.empty(3)
    e[:2] = RmT @ (r_t - m_t)
    e[2] = float(wrap_angle(r_yaw - yaw_m))
    H_i = np.zeros((3, 3))
    H_i[:2, :2] = -RmT
    H_i[:2, 2] = RmT @ (-_S @ r_t)
    H_i[2, 2] = -1.0
    cr, sr = np.cos(r_yaw), np.sin(r_yaw)
    H_j = np.zeros((3, 3))
    H_j[:2, :2] = RmT @ np.array([[cr, -sr], [sr, cr]])
    H_j[2, 2] = 1.0
    H_d = np.zeros((3, 1))
    H_d[:2, 0] = RmT @ (-_S @ m_t)
    H_s = np.zeros((3, 1))
    if scale is not None:
        H_s[:2, 0] = -gain * (RmT @ (Rd @ J)) - yaw_raw_rad * (_S @ e[:2])
        H_s[2, 0] = -yaw_raw_rad
    H_k = np.zeros((3, 1))
    H_k[:2, 0] = -RmT @ (Rd @ q)
    return e, H_i, H_j, H_d, H_s, H_k


def odometry_factor(
    key_i: int,
    key_j: int,
    measured: npt.ArrayLike,
    cov: npt.ArrayLike,
    misalignment_key: int | None = None,
    scale_key: int | None = None,
    yaw_raw_rad: float = 0.0,
    d_t_d_scale: npt.ArrayLike | None = None,
    scale0: float = 1.0,
    dvl_scale_key: int | None = None,
) -> gtsam.CustomFactor:
    """Odometry between ``X(i)`` and ``X(j)`` with the DVL misalignment ``D(0)``, the gyro
    scale ``G(0)`` and/or the DVL's scale-factor error ``K(0)`` (size-1 Vectors); see
    :func:`odometry_residual`.

    Parameters
    ----------
    measured : array_like, shape (3,)
        Relative pose ``iTj`` integrated with ``delta = 0`` and ``s = scale0``.
    cov : array_like, shape (3, 3)
        Covariance of the error of :func:`odometry_residual` (the frame of ``measured``).
    misalignment_key, scale_key : int or None
        Keys of ``D(0)`` and ``G(0)``; None leaves that term out (``delta = 0``, ``s = scale0``).
    yaw_raw_rad : float
        The gyro's integral over the interval (rad), for the scale.
    d_t_d_scale : array_like, shape (2,)
        Derivative of the translation with respect to the scale (m).
    scale0 : float
        The scale ``measured`` was integrated with.
    dvl_scale_key : int or None
        Key of ``K(0)``; None: ``k = 0``.
    """
    m = np.asarray(measured, dtype=np.float64).copy()
    J = None if d_t_d_scale is None else np.asarray(d_t_d_scale, dtype=np.float64).copy()
    keys = [key_i, key_j]
    if misalignment_key is not None:
        keys.append(misalignment_key)
    i_delta = i_scale = i_k = None
    if misalignment_key is not None:
        i_delta = len(keys) - 1
    if scale_key is not None:
        keys.append(scale_key)
        i_scale = len(keys) - 1
    if dvl_scale_key is not None:
        keys.append(dvl_scale_key)
        i_k = len(keys) - 1
    yaw_raw, s0 = float(yaw_raw_rad), float(scale0)

    def error(this: gtsam.CustomFactor, values: gtsam.Values, H: Any) -> FloatArray:
        k = this.keys()
        pi, pj = values.atPose2(k[0]), values.atPose2(k[1])
        delta = 0.0 if i_delta is None else float(values.atVector(k[i_delta])[0])
        scale = None if i_scale is None else float(values.atVector(k[i_scale])[0])
        dvl_k = 0.0 if i_k is None else float(values.atVector(k[i_k])[0])
        e, H_i, H_j, H_d, H_s, H_k = odometry_residual(
            m,
            np.array([pi.x(), pi.y(), pi.theta()]),
            np.array([pj.x(), pj.y(), pj.theta()]),
            delta,
            scale,
            yaw_raw,
            J,
            s0,
            dvl_k,
        )
        if H is not None:
            H[0] = H_i
            H[1] = H_j
            if i_delta is not None:
                H[i_delta] = H_d
            if i_scale is not None:
                H[i_scale] = H_s
            if i_k is not None:
                H[i_k] = H_k
        return e

    return gtsam.CustomFactor(noise_model(cov), keys, error)


def _with_calibration(
    keys: list[int], mount_key: int | None, scale_key: int | None
) -> tuple[list[int], int | None, int | None]:
    """``keys`` with the mounting's and the range scale's keys appended where they are
    variables, and the positions of the two (None: a constant)."""
    i_mount = i_scale = None
    if mount_key is not None:
        keys.append(mount_key)
        i_mount = len(keys) - 1
    if scale_key is not None:
        keys.append(scale_key)
        i_scale = len(keys) - 1
    return keys, i_mount, i_scale


def _calibration(
    values: gtsam.Values, k: Any, i_mount: int | None, i_scale: int | None, bTs: FloatArray
) -> tuple[FloatArray, float]:
    """The mounting ``(x_m, y_m, yaw_rad)`` and the range scale at ``values`` (the constant
    ``bTs`` and 1 where they are not variables)."""
    mount = bTs if i_mount is None else np.asarray(values.atVector(k[i_mount]))
    scale = 1.0 if i_scale is None else float(values.atVector(k[i_scale])[0])
    return mount, scale


def _set_calibration_jacobians(
    H: Any, i_mount: int | None, i_scale: int | None, H_mount: FloatArray, H_scale: FloatArray
) -> None:
    """The error's Jacobians in the mounting and the range scale, where they are variables."""
    if i_mount is not None:
        H[i_mount] = H_mount
    if i_scale is not None:
        H[i_scale] = H_scale
