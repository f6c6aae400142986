"""The factor graph's association belief: which landmarks a vote's observations could be of, and
their joint covariance with the current pose.

The factor graph computes joint marginals for its association (an iSAM2 query per vote); only
the landmarks individually compatible with some observation under a loose gate take part
(:func:`loose_distances`). The gate uses the current pose covariance and each landmark's cached
marginal, without their cross-covariance (conservative: it is positive between a pose and the
lines it has seen). The joint marginal of the newest optimised node and the candidates is then
carried to the current time by the odometry (:func:`joint_covariance`).
"""

from __future__ import annotations

import numpy as np

from sonarslam.features.geometry import FloatArray, compose_jacobians, wrap_angle
from sonarslam.slam.model.lines import line_predictions, local_to_world
from sonarslam.slam.model.motion import RelativeMotion

__all__ = ["loose_distances", "joint_covariance"]


def loose_distances(
    z: FloatArray,
    R: FloatArray,
    wTb: FloatArray,
    P_pose: FloatArray,
    lines_w: FloatArray,
    line_covs: FloatArray,
    bTs: FloatArray,
) -> FloatArray:
    """Smallest squared Mahalanobis distance of each landmark to any observation.

    Parameters
    ----------
    z : ndarray, shape (m, 2)
        Observed lines in the sonar frame.
    R : ndarray, shape (m, 2, 2)
        Their covariances.
    wTb : ndarray, shape (3,)
        Current pose, with ``P_pose`` (3, 3) its covariance.
    lines_w : ndarray, shape (k, 2)
        Landmark lines as stored, with ``line_covs`` (k, 2, 2) their (cached) marginals.
    bTs : ndarray, shape (3,)

    Returns
    -------
    ndarray, shape (k,)
        Per landmark, the distance of its nearest observation (sign-free: each pairing in the
        representation of ``z`` nearest the prediction).
    """
    z_hat, Hp, H_line = line_predictions(wTb, lines_w, bTs)
    S0 = np.einsum("kab,bc,kdc->kad", Hp, P_pose, Hp) + np.einsum(
        "kab,kbc,kdc->kad", H_line, line_covs, H_line
    )
    # innovations of every (observation, landmark), in the representation of z nearest z_hat
    d_theta = wrap_angle(z[:, None, 1] - z_hat[None, :, 1])
    flip = np.abs(d_theta) > 0.5 * np.pi
    nu_rho = np.where(flip, -z[:, None, 0], z[:, None, 0]) - z_hat[None, :, 0]
    nu_theta = np.where(flip, wrap_angle(d_theta + np.pi), d_theta)
    S = S0[None] + R[:, None]
    s01 = np.where(flip, -S[..., 0, 1], S[..., 0, 1])  # diag(-1, 1) R diag(-1, 1)
    s01 = s01 + np.where(flip, S0[None, :, 0, 1] * 2.0, 0.0)  # S0 is not flipped
    s00, s11 = S[..., 0, 0], S[..., 1, 1]
    det = s00 * s11 - s01 * s01
    d2 = (s11 * nu_rho**2 - 2.0 * s01 * nu_rho * nu_theta + s00 * nu_theta**2) / det
    return np.asarray(d2.min(axis=0))


def joint_covariance(
    J_local: FloatArray, anchor_wTb: FloatArray, since_anchor: RelativeMotion
) -> FloatArray:
    """Joint covariance of ``[current pose (x, y, yaw), candidate lines]`` (m, rad).

    Parameters
    ----------
    J_local : ndarray, shape (3 + 2k, 3 + 2k)
        iSAM2's joint marginal of the anchor (newest optimised node, in its local tangent) and
        the candidate lines.
    anchor_wTb : ndarray, shape (3,)
        The anchor's pose.
    since_anchor : RelativeMotion
        The odometry since the anchor, with its covariance.

    Returns
    -------
    ndarray, shape (3 + 2k, 3 + 2k)
        The anchor mapped to world coordinates and composed with the odometry since it
        (:func:`sonarslam.features.geometry.compose_jacobians`).
    """
    n = J_local.shape[0]
    T = np.eye(n)
    J_a, J_b = compose_jacobians(anchor_wTb, since_anchor.pose)
    T[:3, :3] = J_a @ local_to_world(float(anchor_wTb[2]))
    P = T @ J_local @ T.T
    P[:3, :3] += J_b @ since_anchor.cov @ J_b.T
    return P
