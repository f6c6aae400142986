"""Observation models with the sonar's calibration as state: its mounting ``bTs`` and its range
scale ``s``.

The sonar logs an echo from true range ``r`` at ``s * r`` (a sound-speed error): every point it
sees is scaled by ``s`` about the sonar head, which leaves directions as they are. So

* a line ``(rho, theta)`` in the sonar frame is seen as ``(s * rho, theta)``
  (:func:`line_prediction_calibrated`, its residual :func:`line_residual_calibrated`; a seen
  line back in the world, a new landmark's estimate: :func:`world_line_calibrated`);
* a scan registration, made between scans whose points were put in the body frame with the
  *assumed* mounting ``a`` (the front end's), measures the relative pose of the two sonar frames
  ``sTs' = bTs^-1 * bTb' * bTs`` with its translation scaled by ``s``, expressed back through
  ``a``: ``h = a * S_s(bTs^-1 * iTj * bTs) * a^-1`` (:func:`scan_residual`). At ``bTs = a`` and
  ``s = 1`` it is ``iTj``, the plain ``BetweenFactorPose2``. (The scans' motion correction
  within a scan is left to first order.)

Jacobians are analytic, with respect to the poses in GTSAM's local tangent
(:func:`sonarslam.slam.model.lines.local_to_world`) for the residuals and in plain ``(x, y,
yaw)`` for the prediction and the world line (the EKF's state), to the mounting in plain ``(x,
y, yaw)`` (it is a 3-vector variable) and to the scale; ``tests/test_calibration_state.py`` and
``tests/test_ekf_calibration.py`` check them numerically.
"""

from __future__ import annotations

import numpy as np

from sonarslam.features.geometry import (
    FLIP_RHO,
    FloatArray,
    compose,
    compose_jacobians,
    inverse,
    line_difference,
    line_frame_to_world,
    line_world_to_frame,
    wrap_angle,
)
from sonarslam.slam.model.lines import local_to_world

__all__ = [
    "inverse_jacobian",
    "line_prediction_calibrated",
    "line_residual_calibrated",
    "world_line_calibrated",
    "scan_prediction",
    "scan_residual",
]


def inverse_jacobian(aTb: FloatArray) -> FloatArray:
    """``d inverse(aTb) / d aTb`` in plain ``(x, y, yaw)``, shape (3, 3)."""
    c, s = np.cos(aTb[2]), np.sin(aTb[2])
    x, y = aTb[0], aTb[1]
    return np.array([[-c, -s, s * x - c * y], [s, -c, c * x + s * y], [0.0, 0.0, -1.0]])


def line_prediction_calibrated(
    wTb: FloatArray, line_w: FloatArray, bTs: FloatArray, range_scale: float
) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray, FloatArray]:
    """The world line ``line_w`` as the sonar at ``wTs = wTb * bTs`` logs it: the line in that
    frame with its ``rho`` times ``range_scale`` (module docstring), and its Jacobians.

    At ``range_scale = 1`` it is :func:`sonarslam.slam.model.lines.line_prediction`.

    Parameters
    ----------
    wTb : ndarray, shape (3,)
        Body pose ``(x_m, y_m, yaw_rad)``.
    line_w : ndarray, shape (2,)
        World line ``(rho_m, theta_rad)``.
    bTs : ndarray, shape (3,)
        Sonar mounting ``(x_m, y_m, yaw_rad)``.
    range_scale : float
        The sonar's range scale ``s`` (> 0).

    Returns
    -------
    z_hat : ndarray, shape (2,)
        Normalised predicted line ``(rho_m, theta_rad)`` in the sonar frame.
    H_pose : ndarray, shape (2, 3)
        ``d z_hat / d wTb`` in plain ``(x, y, yaw)``.
    H_line : ndarray, shape (2, 2)
        ``d z_hat / d line_w``.
    H_mount : ndarray, shape (2, 3)
        ``d z_hat / d bTs`` in plain ``(x, y, yaw)``.
    H_scale : ndarray, shape (2, 1)
        ``d z_hat / d range_scale``.
    """
    J_b, J_m = compose_jacobians(wTb, bTs)
    z0, H_line, H_sensor = line_world_to_frame(line_w, compose(wTb, bTs))
    Dg = np.diag([range_scale, 1.0])
    DH = Dg @ H_sensor
    return Dg @ z0, DH @ J_b, Dg @ H_line, DH @ J_m, np.array([[z0[0]], [0.0]])


def world_line_calibrated(
    z: FloatArray, wTb: FloatArray, bTs: FloatArray, range_scale: float
) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray, FloatArray]:
    """The world line a logged line ``z`` stands for, seen from body pose ``wTb`` by a sonar
    mounted at ``bTs`` with range scale ``range_scale``: the inverse of
    :func:`line_prediction_calibrated` (``z``'s ``rho`` divided by the scale, then the line
    put in the world from ``wTs = wTb * bTs``), and its Jacobians (a new landmark's estimate
    and its cross-covariances).

    Parameters
    ----------
    z : ndarray, shape (2,)
        Logged line ``(rho_m, theta_rad)`` in the sonar frame.
    wTb, bTs : ndarray, shape (3,)
        Body pose and sonar mounting ``(x_m, y_m, yaw_rad)``.
    range_scale : float
        The sonar's range scale ``s`` (> 0).

    Returns
    -------
    line_w : ndarray, shape (2,)
        Normalised world line ``(rho_m, theta_rad)``.
    G_z : ndarray, shape (2, 2)
        ``d line_w / d z``.
    G_pose : ndarray, shape (2, 3)
        ``d line_w / d wTb`` in plain ``(x, y, yaw)``.
    G_mount : ndarray, shape (2, 3)
        ``d line_w / d bTs`` in plain ``(x, y, yaw)``.
    G_scale : ndarray, shape (2, 1)
        ``d line_w / d range_scale``.
    """
    zz = np.asarray(z, dtype=np.float64)
    line_w, G_line, G_sensor = line_frame_to_world(
        np.array([zz[0] / range_scale, zz[1]]), compose(wTb, bTs)
    )
    J_b, J_m = compose_jacobians(wTb, bTs)
    G_z = G_line @ np.diag([1.0 / range_scale, 1.0])
    G_scale = G_line @ np.array([[-zz[0] / range_scale**2], [0.0]])
    return line_w, G_z, G_sensor @ J_b, G_sensor @ J_m, G_scale


def line_residual_calibrated(
    z: FloatArray,
    wTk: FloatArray,
    line_w: FloatArray,
    kTb: FloatArray,
    bTs: FloatArray,
    range_scale: float,
) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray, FloatArray]:
    """Error of a line observation with the mounting and range scale as variables.

    The sonar is at ``wTs = wTk * kTb * bTs``: ``wTk`` the node's body pose, ``kTb`` the body's
    pose at the observation in the node's frame (the odometry since the node, a constant),
    ``bTs`` the mounting. The prediction is the world line in that frame with its ``rho`` times
    ``range_scale``; the error is measured minus predicted with the sign ambiguity resolved as
    in :func:`sonarslam.slam.model.lines.line_residual` (which this is at ``kTb = 0``,
    ``range_scale = 1``).

    Parameters
    ----------
    z : ndarray, shape (2,)
        Measured line ``(rho_m, theta_rad)`` in the sonar frame.
    wTk : ndarray, shape (3,)
    line_w : ndarray, shape (2,)
    kTb, bTs : ndarray, shape (3,)
    range_scale : float

    Returns
    -------
    e : ndarray, shape (2,)
    H_pose : ndarray, shape (2, 3)
        In the local tangent of ``wTk``.
    H_line : ndarray, shape (2, 2)
    H_mount : ndarray, shape (2, 3)
        ``d e / d bTs`` in plain ``(x, y, yaw)``.
    H_scale : ndarray, shape (2, 1)
    """
    wTb = compose(wTk, kTb)
    J_k, _ = compose_jacobians(wTk, kTb)
    z_hat, H_b, H_l, H_mount, H_s = line_prediction_calibrated(wTb, line_w, bTs, range_scale)
    H_pose = H_b @ J_k @ local_to_world(float(wTk[2]))
    nu, flipped = line_difference(z, z_hat)
    F = FLIP_RHO if flipped else np.eye(2)
    return F @ nu, -F @ H_pose, -F @ H_l, -F @ H_mount, -F @ H_s


def scan_prediction(
    iTj: FloatArray, bTs: FloatArray, range_scale: float, bTs_assumed: FloatArray
) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    """The relative pose a scan registration measures for body motion ``iTj`` (module
    docstring), ``h = a * S_s(bTs^-1 * iTj * bTs) * a^-1`` with ``a = bTs_assumed``.

    Returns
    -------
    h : ndarray, shape (3,)
    H_rel : ndarray, shape (3, 3)
        ``d h / d iTj`` (plain).
    H_mount : ndarray, shape (3, 3)
        ``d h / d bTs`` (plain).
    H_scale : ndarray, shape (3, 1)
    """
    c_inv = inverse(bTs)
    u = compose(c_inv, iTj)
    q = compose(u, bTs)
    Ju_cinv, Ju_r = compose_jacobians(c_inv, iTj)
    Jq_u, Jq_c = compose_jacobians(u, bTs)
    dq_dc = Jq_u @ Ju_cinv @ inverse_jacobian(bTs) + Jq_c
    dq_dr = Jq_u @ Ju_r
    Ds = np.diag([range_scale, range_scale, 1.0])
    qs = Ds @ q
    a = np.asarray(bTs_assumed, dtype=np.float64)
    v = compose(a, qs)
    _, Jv_qs = compose_jacobians(a, qs)
    Jh_v, _ = compose_jacobians(v, inverse(a))
    h = compose(v, inverse(a))
    G = Jh_v @ Jv_qs
    return h, G @ Ds @ dq_dr, G @ Ds @ dq_dc, G @ np.array([[q[0]], [q[1]], [0.0]])


def scan_residual(
    z: FloatArray,
    wTi: FloatArray,
    wTj: FloatArray,
    bTs: FloatArray,
    range_scale: float,
    bTs_assumed: FloatArray,
) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray, FloatArray]:
    """Error of a scan registration ``z`` between body nodes ``wTi``, ``wTj``:
    ``(R(z_yaw)^T (h_t - z_t), wrap(h_yaw - z_yaw))`` with ``h`` :func:`scan_prediction` of
    ``iTj = wTi^-1 wTj``, the first-order equivalent of ``BetweenFactorPose2``'s error (its
    covariance is in the same frame).

    Returns
    -------
    e : ndarray, shape (3,)
    H_i, H_j : ndarray, shape (3, 3)
        In the local tangents of ``wTi`` and ``wTj``.
    H_mount : ndarray, shape (3, 3)
        Plain ``(x, y, yaw)`` of ``bTs``.
    H_scale : ndarray, shape (3, 1)
    """
    wTi_inv = inverse(wTi)
    iTj = compose(wTi_inv, wTj)
    Jr_inv, Jr_j = compose_jacobians(wTi_inv, wTj)
    h, H_rel, H_mount, H_scale = scan_prediction(iTj, bTs, range_scale, bTs_assumed)
    cz, sz = np.cos(z[2]), np.sin(z[2])
    E = np.array([[cz, sz, 0.0], [-sz, cz, 0.0], [0.0, 0.0, 1.0]])
    e = np.empty(3)
    e[:2] = E[:2, :2] @ (h[:2] - np.asarray(z[:2]))
    e[2] = float(wrap_angle(h[2] - z[2]))
    H_i = E @ H_rel @ Jr_inv @ inverse_jacobian(wTi) @ local_to_world(float(wTi[2]))
    H_j = E @ H_rel @ Jr_j @ local_to_world(float(wTj[2]))
    return e, H_i, H_j, E @ H_mount, E @ H_scale
