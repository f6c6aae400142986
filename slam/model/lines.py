"""The line observation model shared by every back end (design.md conventions).

A world line ``L = (rho_w, theta_w)`` seen by the sonar at ``wTs = wTb * bTs`` is
``z = line_world_to_frame(L, wTs)`` (:mod:`sonarslam.features.geometry`), normalised. This module gives
that prediction with its Jacobians for one line (:func:`line_prediction`) or many
(:func:`line_predictions`), the residual of a measured line against it with the sign ambiguity
resolved (:func:`line_residual`, the factor graph's error), the world line an observation
stands for with its covariance (:func:`world_observation`, a new landmark's estimate), and which
side of a line the sonar is on (:func:`sonar_side`).

Jacobians with respect to the pose are in plain ``(x, y, yaw)`` coordinates, except
:func:`line_residual`'s, which are in the local tangent of ``wTb`` (GTSAM's ``Pose2``
convention, :func:`local_to_world`). All are checked numerically in the tests.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt

from sonarslam.features.geometry import (
    FLIP_RHO,
    FloatArray,
    compose,
    compose_jacobians,
    line_difference,
    line_frame_to_world,
    line_side,
    line_world_to_frame,
    transform_points,
    wrap_angle,
)
from sonarslam.features.line import LineFeature, check_mounting

__all__ = [
    "local_to_world",
    "local_to_world_covariance",
    "check_mounting_pose",
    "check_pose_radians",
    "line_prediction",
    "line_predictions",
    "line_residual",
    "WorldObservation",
    "world_observation",
    "sonar_side",
    "VoteObservations",
    "usable_observations",
]


def local_to_world(yaw_rad: float) -> FloatArray:
    """``d (x, y, yaw) / d xi`` of ``Pose2.retract(xi)`` at ``xi = 0``: ``blockdiag(R(yaw), 1)``."""
    c, s = np.cos(yaw_rad), np.sin(yaw_rad)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def local_to_world_covariance(wTb: npt.ArrayLike, cov_local: npt.ArrayLike) -> FloatArray:
    """A covariance whose first three rows and columns are a ``Pose2``'s, from GTSAM's local
    (body-frame) tangent to plain world coordinates ``(x_m, y_m, yaw_rad)``.

    GTSAM perturbs a pose ``wTb`` as ``wTb.retract(xi) = wTb * Exp(xi)`` with
    ``xi = (dx_b, dy_b, dtheta)`` in the body frame, so its marginals (``ISAM2``, ``Marginals``)
    of a ``Pose2`` are the covariance of ``xi``. To first order the world pose moves by
    ``T xi`` with ``T = blockdiag(R(yaw), 1)`` (:func:`local_to_world`); the covariance in the
    world is ``A C A^T`` with ``A = blockdiag(T, I)``: the pose block ``T C_pp T^T``, its cross
    terms ``T C_pl``, the rest (vector variables, whose tangent is the world's) unchanged.

    Parameters
    ----------
    wTb : array_like, shape (3,)
        The pose ``(x_m, y_m, yaw_rad)`` the covariance is about (only its yaw is used).
    cov_local : array_like, shape (n, n), n >= 3
        Joint covariance of ``[pose in the local tangent, other variables]``.

    Returns
    -------
    ndarray, shape (n, n)
        The same covariance with the pose in ``(x_m, y_m, yaw_rad)``.
    """
    cov = np.asarray(cov_local, dtype=np.float64)
    if cov.ndim != 2 or cov.shape[0] != cov.shape[1] or cov.shape[0] < 3:
        raise ValueError(f"cov_local must be square, (n, n) with n >= 3, got {cov.shape}")
    A = np.eye(cov.shape[0])
    A[:3, :3] = local_to_world(float(np.asarray(wTb, dtype=np.float64)[2]))
    return A @ cov @ A.T


def check_pose_radians(pose: npt.ArrayLike, where: str, hint: str) -> FloatArray:
    """A pose ``(x_m, y_m, yaw_rad)`` as 3 finite floats with the yaw in radians.

    Parameters
    ----------
    pose : array_like, shape (3,)
    where : str
        Names the parameter in the message (``"line_prediction(bTs=...)"``).
    hint : str
        What a yaw beyond ``2 pi`` likely is, for the message (``"degrees? np.radians"``).

    Returns
    -------
    ndarray, shape (3,)

    Raises
    ------
    ValueError
        Not 3 finite numbers, or a yaw beyond ``2 pi`` in magnitude (degrees given for
        radians), naming ``where`` and the value.
    """
    p = np.asarray(pose, dtype=np.float64)
    if p.shape != (3,) or not np.all(np.isfinite(p)):
        raise ValueError(f"{where} must be 3 finite numbers, got {pose!r}")
    if abs(p[2]) > 2.0 * np.pi:
        raise ValueError(
            f"{where}'s yaw must be in radians within [-2 pi, 2 pi], got {float(p[2])} ({hint})"
        )
    return p


def check_mounting_pose(bTs: npt.ArrayLike, where: str) -> FloatArray:
    """A sonar mounting ``(x_m, y_m, yaw_rad)`` given to a line model, checked by
    :func:`check_pose_radians` (``where`` names the parameter)."""
    return check_pose_radians(
        bTs,
        f"{where}: the sonar mounting",
        "degrees? np.radians; the lines' LineFeature.bTs is the extractor's mounting",
    )


def line_prediction(
    wTb: FloatArray, line_w: FloatArray, bTs: FloatArray
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """The line ``line_w`` seen by the sonar at ``wTs = wTb * bTs``, and its Jacobians.

    Parameters
    ----------
    wTb : ndarray, shape (3,)
        Body pose ``(x_m, y_m, yaw_rad)``.
    line_w : ndarray, shape (2,)
        World line ``(rho_m, theta_rad)`` (need not be normalised).
    bTs : ndarray, shape (3,)
        Sonar mounting ``(x_m, y_m, yaw_rad)``: the lines' extractor's
        (:attr:`sonarslam.features.line.LineFeature.bTs`); a yaw beyond ``2 pi`` in magnitude
        is refused (ValueError, :func:`check_mounting_pose`).

    Returns
    -------
    z_hat : ndarray, shape (2,)
        Normalised line in the sonar frame.
    H_pose : ndarray, shape (2, 3)
        ``d z_hat / d wTb`` in ``(x, y, yaw)``.
    H_line : ndarray, shape (2, 2)
        ``d z_hat / d line_w``.
    """
    bTs = check_mounting_pose(bTs, "line_prediction(bTs=...)")
    wTs = compose(wTb, bTs)
    z_hat, H_line, H_sensor = line_world_to_frame(line_w, wTs)
    J_b, _ = compose_jacobians(wTb, bTs)
    return z_hat, H_sensor @ J_b, H_line


def line_predictions(
    wTb: FloatArray, lines_w: FloatArray, bTs: FloatArray
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """:func:`line_prediction` of many lines from one pose (vectorised).

    Parameters
    ----------
    wTb : ndarray, shape (3,)
    lines_w : ndarray, shape (K, 2)
    bTs : ndarray, shape (3,)
        Refused as by :func:`line_prediction`.

    Returns
    -------
    z_hat : ndarray, shape (K, 2)
    H_pose : ndarray, shape (K, 2, 3)
        In ``(x, y, yaw)``.
    H_line : ndarray, shape (K, 2, 2)
    """
    bTs = check_mounting_pose(bTs, "line_predictions(bTs=...)")
    x, y, psi = compose(wTb, bTs)
    J_b, _ = compose_jacobians(wTb, bTs)
    lw = np.asarray(lines_w, dtype=np.float64).reshape(-1, 2)
    c, s = np.cos(lw[:, 1]), np.sin(lw[:, 1])
    rho_r = lw[:, 0] - x * c - y * s
    sign = np.where(rho_r < 0.0, -1.0, 1.0)
    k = lw.shape[0]
    H_line = np.zeros((k, 2, 2))
    H_line[:, 0, 0] = sign
    H_line[:, 0, 1] = sign * (x * s - y * c)
    H_line[:, 1, 1] = 1.0
    H_sensor = np.zeros((k, 2, 3))
    H_sensor[:, 0, 0] = -sign * c
    H_sensor[:, 0, 1] = -sign * s
    H_sensor[:, 1, 2] = -1.0
    z_hat = np.column_stack(
        [np.abs(rho_r), wrap_angle(lw[:, 1] - psi + np.where(rho_r < 0.0, np.pi, 0.0))]
    )
    return z_hat, H_sensor @ J_b, H_line


def line_residual(
    z: FloatArray, wTb: FloatArray, line_w: FloatArray, bTs: FloatArray
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Error of a line observation: measured minus predicted, in the sonar frame R.

    ``e = z - z_hat`` with ``z_hat`` in the representation nearest ``z``
    (:func:`sonarslam.features.geometry.line_difference`, with the prediction flipped rather than the
    measurement, so that ``e ~ N(0, R)`` with the measurement's own covariance ``R``).

    Returns
    -------
    e : ndarray, shape (2,)
    H_pose : ndarray, shape (2, 3)
        ``d e / d xi`` (local tangent of ``wTb``).
    H_line : ndarray, shape (2, 2)
        ``d e / d line_w``.
    """
    z_hat, H_pose, H_line = line_prediction(wTb, line_w, bTs)
    H_local = H_pose @ local_to_world(float(wTb[2]))
    nu, flipped = line_difference(z, z_hat)
    if not flipped:
        return nu, -H_local, -H_line
    # z was taken as (-rho, theta + pi): flipping z_hat instead is FLIP_RHO on the difference
    return FLIP_RHO @ nu, -FLIP_RHO @ H_local, -FLIP_RHO @ H_line


@dataclass(frozen=True, eq=False)
class WorldObservation:
    """A line observation expressed in the world, with its first-order uncertainty.

    Attributes
    ----------
    line_w : ndarray, shape (2,)
        Normalised world line ``(rho_m, theta_rad)``.
    cov_w : ndarray, shape (2, 2)
        Its covariance: the observation's and the pose's, ``G_z R G_z^T + G_pose P G_pose^T``.
    ends_w : ndarray, shape (2, 2)
        The observed segment's end points in the world (m).
    G_z : ndarray, shape (2, 2)
        ``d line_w / d z``.
    G_pose : ndarray, shape (2, 3)
        ``d line_w / d wTb`` in ``(x, y, yaw)``.
    """

    line_w: FloatArray
    cov_w: FloatArray
    ends_w: FloatArray
    G_z: FloatArray
    G_pose: FloatArray


def world_observation(
    feature: LineFeature,
    wTb: FloatArray,
    P_pose: FloatArray,
    bTs: FloatArray,
    cov_scale: float = 1.0,
) -> WorldObservation:
    """The world line of an observation made from body pose ``wTb`` (covariance ``P_pose``):
    a new landmark's line and its first-order covariance (a filter's augmentation).

    Parameters
    ----------
    feature : LineFeature
        The observation: ``(rho_m, theta_rad)`` and its covariance in the sonar frame,
        ``endpoints_r`` (2, 2) its segment there.
    wTb : ndarray, shape (3,)
        Body pose ``(x_m, y_m, yaw_rad)`` it was made from.
    P_pose : ndarray, shape (3, 3)
        That pose's covariance in ``(x_m, y_m, yaw_rad)``.
    bTs : ndarray, shape (3,)
        Sonar mounting in the body frame: the one ``feature`` was extracted with (its ``bTs``;
        another is refused, ValueError naming it).
    cov_scale : float
        Multiplies the observation's covariance (the back ends' ``line_cov_scale``).

    Returns
    -------
    WorldObservation
        The normalised world line, its covariance, the segment's world end points and the
        Jacobians ``G_z`` (2, 2) and ``G_pose`` (2, 3) (the cross-covariance of the new line
        with the state is ``G_pose P[pose, :]``).
    """
    check_mounting([feature], bTs, "world_observation(bTs=...)")
    wTs = compose(wTb, bTs)
    line_w, G_z, G_sensor = line_frame_to_world(feature.z, wTs)
    J_pose, _ = compose_jacobians(wTb, bTs)
    G_pose = G_sensor @ J_pose
    R = np.asarray(feature.cov) if cov_scale == 1.0 else cov_scale * np.asarray(feature.cov)
    cov_w = G_pose @ P_pose @ G_pose.T + G_z @ R @ G_z.T
    return WorldObservation(line_w, cov_w, transform_points(wTs, feature.endpoints_r), G_z, G_pose)


def sonar_side(wTb: FloatArray, lines_w: npt.ArrayLike, bTs: FloatArray) -> FloatArray:
    """Which side of each world line the sonar is on: ``sign(rho_w - n_w . p_sonar)``.

    A wall is seen from its water side only, so an observation from the other side of a
    landmark's line is another wall (the two faces of a jetty, parallel a few metres apart,
    are one line each with the same ``theta``: only this tells them apart when the pose is
    uncertain by metres).

    Parameters
    ----------
    wTb : ndarray, shape (3,)
    lines_w : ndarray, shape (K, 2)
        World lines as stored (not necessarily normalised).
    bTs : ndarray, shape (3,)

    Returns
    -------
    ndarray, shape (K,)
        +1 or -1.
    """
    x, y, _ = compose(wTb, bTs)
    return line_side(np.asarray(lines_w, dtype=np.float64).reshape(-1, 2), np.array([x, y]))


@dataclass(frozen=True, eq=False)
class VoteObservations:
    """A vote's lines as the landmark layer may use them (:func:`usable_observations`).

    Attributes
    ----------
    features : list of LineFeature
        Those at ``rho_m >= min_rho_m``.
    rejected_near : int
        How many were nearer.
    z : ndarray, shape (m, 2)
        ``features``' lines in the sonar frame ``(rho_m, theta_rad)``.
    R : ndarray, shape (m, 2, 2)
        Their covariances times ``line_cov_scale``.
    """

    features: list[LineFeature]
    rejected_near: int
    z: FloatArray = field(repr=False)
    R: FloatArray = field(repr=False)


def usable_observations(
    features: list[LineFeature], min_rho_m: float, line_cov_scale: float
) -> VoteObservations:
    """The lines of one vote the landmark layer may use: those at least ``min_rho_m`` from the
    sonar, their covariances times ``line_cov_scale`` (the landmark layer's settings)."""
    use = [f for f in features if f.rho_m >= min_rho_m]
    z = np.array([f.z for f in use]).reshape(-1, 2)
    R = np.array([f.cov for f in use]).reshape(-1, 2, 2)
    if line_cov_scale != 1.0:
        R = R * line_cov_scale
    return VoteObservations(use, len(features) - len(use), z, R)
