"""Planar geometry conventions of the project, one function each.

Conventions (see ``docs/design.md``):

* A pose is an array ``(x_m, y_m, yaw_rad)`` of frame ``b`` in frame ``a`` (``aTb``); yaw is
  counter-clockwise from the x axis of ``a``, as ``gtsam.Pose2``.
* A line in a frame is the set of points ``p`` with ``p . (cos theta, sin theta) = rho``,
  normalised to ``rho >= 0`` and ``theta`` in ``[-pi, pi)`` by :func:`normalize_line`.
* A world line seen from pose ``(x, y, psi)``::

      theta_r = theta_w - psi
      rho_r   = rho_w - x cos(theta_w) - y sin(theta_w)

  then normalised (:func:`line_world_to_frame`); its inverse is :func:`line_frame_to_world`.
  Both return their analytic Jacobians, checked numerically in ``tests/test_geometry.py``.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from sonarslam.sonar.beam import FloatArray

__all__ = [
    "FloatArray",
    "wrap_angle",
    "normalize_line",
    "FLIP_RHO",
    "normalize_line_cov",
    "line_difference",
    "compose",
    "compose_jacobians",
    "inverse",
    "between",
    "transform_points",
    "line_world_to_frame",
    "line_frame_to_world",
    "interpolate_poses",
    "along_line",
    "segment_on_line",
    "line_side",
]


def wrap_angle(angle_rad: npt.ArrayLike) -> FloatArray:
    """Wrap angles to ``[-pi, pi)``.

    Parameters
    ----------
    angle_rad : array_like
        Angles in radians, any shape.

    Returns
    -------
    ndarray
        Same shape, in ``[-pi, pi)``.
    """
    a = np.asarray(angle_rad, dtype=np.float64)
    return np.asarray((a + np.pi) % (2.0 * np.pi) - np.pi, dtype=np.float64)


def normalize_line(rho_m: npt.ArrayLike, theta_rad: npt.ArrayLike) -> tuple[FloatArray, FloatArray]:
    """Normalise lines to ``rho >= 0`` and ``theta`` in ``[-pi, pi)``.

    A line with negative ``rho`` is the same set of points as ``(-rho, theta + pi)``.

    Parameters
    ----------
    rho_m, theta_rad : array_like
        Line distance (m) and normal angle (rad), broadcastable shapes.

    Returns
    -------
    rho_m, theta_rad : ndarray
        Normalised line parameters.
    """
    rho = np.asarray(rho_m, dtype=np.float64)
    theta = np.asarray(theta_rad, dtype=np.float64)
    flip = rho < 0.0
    return np.where(flip, -rho, rho), wrap_angle(np.where(flip, theta + np.pi, theta))


#: ``(rho, theta) -> (-rho, theta + pi)`` acting on a covariance (``FLIP_RHO @ R @ FLIP_RHO``) or
#: on the rows of a Jacobian (``FLIP_RHO @ H``): the one representation change of a line.
FLIP_RHO = np.diag([-1.0, 1.0])


def normalize_line_cov(line: npt.ArrayLike, cov: npt.ArrayLike) -> tuple[FloatArray, FloatArray]:
    """A line ``(rho_m, theta_rad)`` normalised (:func:`normalize_line`), its 2x2 covariance alike.

    Parameters
    ----------
    line : array_like, shape (2,)
    cov : array_like, shape (2, 2)

    Returns
    -------
    line : ndarray, shape (2,)
    cov : ndarray, shape (2, 2)
        ``FLIP_RHO @ cov @ FLIP_RHO`` when the sign of ``rho`` was flipped, else ``cov``.
    """
    ln = np.asarray(line, dtype=np.float64)
    c = np.asarray(cov, dtype=np.float64)
    rho, theta = normalize_line(ln[0], ln[1])
    out = np.array([float(rho), float(theta)])
    return (out, FLIP_RHO @ c @ FLIP_RHO) if ln[0] < 0.0 else (out, c)


def line_difference(z: npt.ArrayLike, z_ref: npt.ArrayLike) -> tuple[FloatArray, bool]:
    """Sign-free difference of two lines ``z - z_ref``, with ``z`` in its representation nearest
    ``z_ref``.

    A line is both ``(rho, theta)`` and ``(-rho, theta + pi)``; near ``rho = 0`` both are close to
    a normalised reference. The difference is taken in the one whose angle is within ``pi / 2``
    of ``z_ref``'s.

    Parameters
    ----------
    z, z_ref : array_like, shape (2,)
        Lines ``(rho_m, theta_rad)``, any representation.

    Returns
    -------
    nu : ndarray, shape (2,)
        ``(rho_m, theta_rad)`` difference, the angle wrapped.
    flipped : bool
        True when ``z`` was taken as ``(-rho, theta + pi)``: its covariance is then
        ``FLIP_RHO @ R @ FLIP_RHO`` and ``d nu / d z`` is ``FLIP_RHO``.
    """
    zz = np.asarray(z, dtype=np.float64)
    zr = np.asarray(z_ref, dtype=np.float64)
    d_theta = float(wrap_angle(zz[1] - zr[1]))
    if abs(d_theta) <= 0.5 * np.pi:
        return np.array([zz[0] - zr[0], d_theta]), False
    return np.array([-zz[0] - zr[0], float(wrap_angle(zz[1] + np.pi - zr[1]))]), True


def compose(aTb: npt.ArrayLike, bTc: npt.ArrayLike) -> FloatArray:
    """Compose planar poses ``aTc = aTb * bTc``; both arguments broadcast over leading axes.

    Parameters
    ----------
    aTb, bTc : array_like, shape (..., 3)
        Poses ``(x_m, y_m, yaw_rad)``.

    Returns
    -------
    ndarray, shape (..., 3)
    """
    p = np.asarray(aTb, dtype=np.float64)
    q = np.asarray(bTc, dtype=np.float64)
    c, s = np.cos(p[..., 2]), np.sin(p[..., 2])
    x = p[..., 0] + c * q[..., 0] - s * q[..., 1]
    y = p[..., 1] + s * q[..., 0] + c * q[..., 1]
    return np.stack([x, y, wrap_angle(p[..., 2] + q[..., 2])], axis=-1)


def compose_jacobians(aTb: npt.ArrayLike, bTc: npt.ArrayLike) -> tuple[FloatArray, FloatArray]:
    """Jacobians of :func:`compose` ``aTc = aTb * bTc`` in plain (x, y, yaw) coordinates.

    Returns
    -------
    J_a : ndarray, shape (3, 3)
        ``d aTc / d aTb``.
    J_b : ndarray, shape (3, 3)
        ``d aTc / d bTc``.
    """
    p = np.asarray(aTb, dtype=np.float64)
    q = np.asarray(bTc, dtype=np.float64)
    c, s = np.cos(p[2]), np.sin(p[2])
    J_a = np.array(
        [[1.0, 0.0, -s * q[0] - c * q[1]], [0.0, 1.0, c * q[0] - s * q[1]], [0.0, 0.0, 1.0]]
    )
    J_b = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    return J_a, J_b


def inverse(aTb: npt.ArrayLike) -> FloatArray:
    """Inverse pose ``bTa``.

    Parameters
    ----------
    aTb : array_like, shape (..., 3)

    Returns
    -------
    ndarray, shape (..., 3)
    """
    p = np.asarray(aTb, dtype=np.float64)
    c, s = np.cos(p[..., 2]), np.sin(p[..., 2])
    x = -c * p[..., 0] - s * p[..., 1]
    y = s * p[..., 0] - c * p[..., 1]
    return np.stack([x, y, wrap_angle(-p[..., 2])], axis=-1)


def between(wTa: npt.ArrayLike, wTb: npt.ArrayLike) -> FloatArray:
    """Relative pose ``aTb = inverse(wTa) * wTb``."""
    return compose(inverse(wTa), wTb)


def transform_points(aTb: npt.ArrayLike, points_b: npt.ArrayLike) -> FloatArray:
    """Map points from frame ``b`` to frame ``a``.

    Parameters
    ----------
    aTb : array_like, shape (3,) or (N, 3)
        One pose, or one pose per point.
    points_b : array_like, shape (N, 2)
        Points in frame ``b`` (m).

    Returns
    -------
    ndarray, shape (N, 2)
        Points in frame ``a`` (m).
    """
    p = np.asarray(aTb, dtype=np.float64)
    q = np.asarray(points_b, dtype=np.float64)
    c, s = np.cos(p[..., 2]), np.sin(p[..., 2])
    x = p[..., 0] + c * q[..., 0] - s * q[..., 1]
    y = p[..., 1] + s * q[..., 0] + c * q[..., 1]
    return np.stack([x, y], axis=-1)


def line_world_to_frame(
    line_w: npt.ArrayLike, wTr: npt.ArrayLike
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Express a world line in frame ``r`` (the observation model of the back ends).

    Parameters
    ----------
    line_w : array_like, shape (2,)
        World line ``(rho_m, theta_rad)``.
    wTr : array_like, shape (3,)
        Pose of frame ``r`` in the world ``(x_m, y_m, yaw_rad)``.

    Returns
    -------
    line_r : ndarray, shape (2,)
        Normalised line ``(rho_m, theta_rad)`` in frame ``r``.
    H_line : ndarray, shape (2, 2)
        ``d line_r / d line_w``.
    H_pose : ndarray, shape (2, 3)
        ``d line_r / d wTr``.
    """
    lw = np.asarray(line_w, dtype=np.float64)
    rho_w, theta_w = float(lw[0]), float(lw[1])
    x, y, psi = (float(v) for v in np.asarray(wTr, dtype=np.float64))
    c, s = np.cos(theta_w), np.sin(theta_w)
    rho_r = rho_w - x * c - y * s
    theta_r = theta_w - psi
    H_line = np.array([[1.0, x * s - y * c], [0.0, 1.0]])
    H_pose = np.array([[-c, -s, 0.0], [0.0, 0.0, -1.0]])
    sign = -1.0 if rho_r < 0.0 else 1.0
    H_line[0] *= sign
    H_pose[0] *= sign
    rho_n, theta_n = normalize_line(rho_r, theta_r)
    return np.array([float(rho_n), float(theta_n)]), H_line, H_pose


def line_frame_to_world(
    line_r: npt.ArrayLike, wTr: npt.ArrayLike
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Express a line of frame ``r`` in the world (landmark initialisation).

    Parameters
    ----------
    line_r : array_like, shape (2,)
        Line ``(rho_m, theta_rad)`` in frame ``r``.
    wTr : array_like, shape (3,)
        Pose of frame ``r`` in the world.

    Returns
    -------
    line_w : ndarray, shape (2,)
        Normalised world line.
    G_line : ndarray, shape (2, 2)
        ``d line_w / d line_r``.
    G_pose : ndarray, shape (2, 3)
        ``d line_w / d wTr``.
    """
    lr = np.asarray(line_r, dtype=np.float64)
    rho_r, theta_r = float(lr[0]), float(lr[1])
    x, y, psi = (float(v) for v in np.asarray(wTr, dtype=np.float64))
    theta_w = theta_r + psi
    c, s = np.cos(theta_w), np.sin(theta_w)
    rho_w = rho_r + x * c + y * s
    d_theta = -x * s + y * c
    G_line = np.array([[1.0, d_theta], [0.0, 1.0]])
    G_pose = np.array([[c, s, d_theta], [0.0, 0.0, 1.0]])
    sign = -1.0 if rho_w < 0.0 else 1.0
    G_line[0] *= sign
    G_pose[0] *= sign
    rho_n, theta_n = normalize_line(rho_w, theta_w)
    return np.array([float(rho_n), float(theta_n)]), G_line, G_pose


def line_side(lines: npt.ArrayLike, points: npt.ArrayLike) -> FloatArray:
    """Which side of lines points are on: ``+1`` where ``rho - n . p >= 0`` (the side of the
    line's origin when ``rho > 0``), ``-1`` on the side its normal ``n = (cos theta, sin
    theta)`` points to. The one side-of-a-line rule (a wall is seen from its water side only).

    Parameters
    ----------
    lines : array_like, shape (2,) or (K, 2)
        ``(rho_m, theta_rad)``, not necessarily normalised.
    points : array_like, shape (2,) or (K, 2)
        Points in the lines' frame (m); broadcast against ``lines``.

    Returns
    -------
    ndarray, shape () or (K,)
        +1.0 or -1.0.
    """
    ln = np.asarray(lines, dtype=np.float64)
    p = np.asarray(points, dtype=np.float64)
    rho, theta = ln[..., 0], ln[..., 1]
    raw = rho - p[..., 0] * np.cos(theta) - p[..., 1] * np.sin(theta)
    return np.asarray(np.where(raw < 0.0, -1.0, 1.0))


def along_line(line: npt.ArrayLike, points: npt.ArrayLike) -> FloatArray:
    """Coordinate of points along a line's direction ``(-sin theta, cos theta)`` (m).

    Parameters
    ----------
    line : array_like, shape (2,)
        ``(rho_m, theta_rad)``.
    points : array_like, shape (N, 2)
        Points in the line's frame (m).

    Returns
    -------
    ndarray, shape (N,)
        0 at the foot of the normal from the origin.
    """
    ln = np.asarray(line, dtype=np.float64)
    return np.asarray(
        np.asarray(points, dtype=np.float64) @ np.array([-np.sin(ln[1]), np.cos(ln[1])])
    )


def segment_on_line(line: npt.ArrayLike, s_min_m: float, s_max_m: float) -> FloatArray:
    """The two ends of the segment ``[s_min_m, s_max_m]`` of a line (:func:`along_line`), (2, 2)."""
    ln = np.asarray(line, dtype=np.float64)
    foot = ln[0] * np.array([np.cos(ln[1]), np.sin(ln[1])])
    tangent = np.array([-np.sin(ln[1]), np.cos(ln[1])])
    return np.stack([foot + s_min_m * tangent, foot + s_max_m * tangent])


def interpolate_poses(
    t_query_s: npt.ArrayLike,
    t_s: npt.ArrayLike,
    poses: npt.ArrayLike,
    yaw_unwrapped_rad: npt.ArrayLike | None = None,
) -> FloatArray:
    """Linear interpolation of poses in time, yaw through its shortest arc.

    Parameters
    ----------
    t_query_s : array_like, shape (M,)
        Query times (Unix s); outside ``t_s`` the end poses are held.
    t_s : array_like, shape (N,)
        Increasing sample times (Unix s).
    poses : array_like, shape (N, 3)
        Poses at ``t_s``.
    yaw_unwrapped_rad : array_like, shape (N,), optional
        ``np.unwrap(poses[:, 2])``, for callers that interpolate the same poses many times.

    Returns
    -------
    ndarray, shape (M, 3)
    """
    tq = np.atleast_1d(np.asarray(t_query_s, dtype=np.float64))
    t = np.asarray(t_s, dtype=np.float64)
    p = np.asarray(poses, dtype=np.float64)
    yaw = np.unwrap(p[:, 2]) if yaw_unwrapped_rad is None else np.asarray(yaw_unwrapped_rad)
    out = np.empty((tq.size, 3))
    out[:, 0] = np.interp(tq, t, p[:, 0])
    out[:, 1] = np.interp(tq, t, p[:, 1])
    out[:, 2] = wrap_angle(np.interp(tq, t, yaw))
    return out
