"""Observation models with the sonar's calibration as state: its mounting ``bTs`` and its range
scale ``s``.

The sonar logs an echo from true range ``r`` at ``s * r`` (a sound-speed error): every point it
sees is scaled by ``s`` about the sonar head, which leaves directions as they are. So

* a line ``(rho, theta)`` in the sonar frame is seen as ``(s * rho, theta)``
  (:func:`line_residual_calibrated`);
* a scan registration, made between scans whose points were put in the body frame with the
  *assumed* mounting ``a`` (the front end's), measures the relative pose of the two sonar frames
  ``sTs' = bTs^-1 * bTb' * bTs`` with its translation scaled by ``s``, expressed back through
  ``a``: ``h = a * S_s(bTs^-1 * iTj * bTs) * a^-1`` (:func:`scan_residual`). At ``bTs = a`` and
  ``s = 1`` it is ``iTj``, the plain ``BetweenFactorPose2``. (The scans' motion correction
  within a scan is left to first order.)

Jacobians are analytic, with respect to the poses in GTSAM's local tangent
(:func:`sonarslam.slam.model.lines.local_to_world`), to the mounting in plain ``(x, y, yaw)``
(it is a 3-vector variable) and to the scale; ``tests/test_calibration_state.py`` checks them
numerically.
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
    line_world_to_frame,
    wrap_angle,
)
from sonarslam.slam.model.lines import local_to_world

__all__ = ["inverse_jacobian", "line_residual_calibrated", "scan_prediction", "scan_residual"]


def inverse_jacobian(aTb: FloatArray) -> FloatArray:
    """``d inverse(aTb) / d aTb`` in plain ``(x, y, yaw)``, shape (3, 3)."""
    c, s = np.cos(aTb[2]), np.sin(aTb[2])
    x, y = aTb[0], aTb[1]
    return np.array([[-c, -s, s * x - c * y], [s, -c, c * x + s * y], [0.0, 0.0, -1.0]])


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
    J_b, J_m = compose_jacobians(wTb, bTs)
    z0, H_line, H_sensor = line_world_to_frame(line_w, compose(wTb, bTs))
    Dg = np.diag([range_scale, 1.0])
    z_hat = Dg @ z0
    H_pose = Dg @ H_sensor @ J_b @ J_k @ local_to_world(float(wTk[2]))
    H_mount = Dg @ H_sensor @ J_m
    H_l = Dg @ H_line
    H_s = np.array([[z0[0]], [0.0]])
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
