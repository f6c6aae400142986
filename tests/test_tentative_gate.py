"""The tentative-line gate (issue 31): two views of a line are compared with the joint
covariance of the two sonar poses, so that the pose error the views share cancels instead of
counting twice. Against the truth of a seeded scene: two parallel walls 6.7 m apart, seen from a
pose known to 5 m, are not one landmark; one wall seen twice is."""

from __future__ import annotations

import numpy as np
import pytest

from sonarslam.features.geometry import compose, inverse, line_world_to_frame, transform_points
from sonarslam.features.line import LineFeature
from sonarslam.slam.backends.ekf import POSE, EkfConfig, LineEkf
from sonarslam.slam.backends.isam2.graph import GraphConfig, LineIsam2
from sonarslam.slam.mapping.landmarks import LandmarkMap
from sonarslam.slam.mapping.vote import ViewPair
from sonarslam.slam.model.motion import motion_step
from sonarslam.sonar.beam import Mounting

R_LINE = np.diag([0.05**2, np.deg2rad(0.5) ** 2])
SIGMA_XY_M = 5.0  # the start's position sigma: the error both views share
NEAR, FAR = np.array([10.0, 0.0]), np.array([16.7, 0.0])  # x = 10 and x = 16.7, one side


def _backend(kind: str, **settings: object) -> LineEkf | LineIsam2:
    """A back end at the origin whose position is known to ``SIGMA_XY_M``, with the joint
    tentative gate unless a test sets it."""
    settings.setdefault("reobservation_min_move_m", None)
    settings.setdefault("tentative_joint_gate", True)
    pose = np.zeros(3)
    P0 = np.diag([SIGMA_XY_M**2, SIGMA_XY_M**2, 1e-6])
    if kind == "ekf":
        return LineEkf(0.0, pose, P0, Mounting(), EkfConfig(**settings))  # type: ignore[arg-type]
    return LineIsam2(0.0, pose, P0, Mounting(), GraphConfig(**settings))  # type: ignore[arg-type]


def _see(be: LineEkf | LineIsam2, t: float, line_w: np.ndarray, rng: np.random.Generator) -> list:
    """Drive 2 m along the walls (exact odometry: the estimate's error is the start's), then
    one vote seeing ``line_w`` with seeded noise of ``R_LINE``."""
    be.predict(motion_step(t - 4.0, t, np.array([0.0, 0.5]), 0.01, 0.0, t - 4.0))
    wTs = compose(be.pose, be.bTs)
    z = line_world_to_frame(line_w, wTs)[0] + rng.multivariate_normal(np.zeros(2), R_LINE)
    ends_w = np.array([[line_w[0], wTs[1] - 8.0], [line_w[0], wTs[1] + 8.0]])
    ends_r = transform_points(inverse(wTs), ends_w)
    f = LineFeature(t, wTs, float(z[0]), float(z[1]), R_LINE, 40, ends_r, 40)
    return be.update_lines([f])


@pytest.mark.parametrize("kind", ["ekf", "isam2"])
def test_two_parallel_walls_are_not_one_landmark_but_one_wall_seen_twice_is(kind: str) -> None:
    for seed in range(5):
        rng = np.random.default_rng(seed)
        be = _backend(kind)
        assert _see(be, 4.0, NEAR, rng) == [None]  # a tentative line
        assert _see(be, 8.0, FAR, rng) == [None]  # another wall: a tentative line of its own
        assert len(be.map.landmarks) == 0 and len(be.map.tentative) == 2
        assert _see(be, 12.0, FAR, rng) == [0]  # the far wall's second view: a landmark
        assert _see(be, 16.0, NEAR, rng) == [1]  # the near wall's, 12 s after its first
        (far, near) = sorted(be.map_records(), key=lambda r: -r["rho"])
        assert far["rho"] - near["rho"] == pytest.approx(6.7, abs=0.3)
        # the gate of before: each world line with its own pose's 5 m, the shared error
        # counted twice, and the far wall's first view joins the near wall's line
        old = _backend(kind, tentative_joint_gate=False)
        rng = np.random.default_rng(seed)
        assert _see(old, 4.0, NEAR, rng) == [None]
        assert _see(old, 8.0, FAR, rng) == [0]
        assert len(old.map.landmarks) == 1


def test_the_filter_s_cross_covariance_is_the_clone_s() -> None:
    """A still vehicle: the pose now is the pose then plus the steps' noise, so their
    cross-covariance is the pose's covariance then; after a heading update it is that update's
    ``(I - K H)`` times it (the clone kept in the state, computed here by hand)."""
    be = _backend("ekf")
    rng = np.random.default_rng(3)
    be.predict(motion_step(0.0, 1.0, np.zeros(2), 0.01, 0.0, 0.0))
    wTs = compose(be.pose, be.bTs)
    z = line_world_to_frame(NEAR, wTs)[0]
    ends_r = transform_points(inverse(wTs), np.array([[10.0, -5.0], [10.0, 5.0]]))
    be.update_lines([LineFeature(1.0, wTs, float(z[0]), float(z[1]), R_LINE, 40, ends_r, 40)])
    (cand,) = be.map.tentative
    P_then = be.P[POSE, POSE].copy()
    P_full = be.P.copy()
    be.predict(motion_step(1.0, 3.0, np.zeros(2), 0.01, 0.0, 1.0))
    pair = be._view_pair(cand.view)
    assert isinstance(pair, ViewPair)
    np.testing.assert_allclose(pair.cov[:3, 3:], P_then, rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(pair.cov[3:, 3:], P_then, rtol=1e-12, atol=1e-15)
    assert np.trace(pair.cov[:3, :3]) > np.trace(P_then)
    # a heading update: the augmented state [s, x_then] and its exact Kalman update
    P = be.P.copy()
    n = P.shape[0]
    Pa = np.zeros((n + 3, n + 3))
    Pa[:n, :n] = P
    Pa[:n, n:] = P_full[:, POSE]  # F = I over the still steps: Cov(s, x_then) unchanged
    Pa[n:, :n] = Pa[:n, n:].T
    Pa[n:, n:] = P_then
    h = np.zeros(n + 3)
    h[[2, 3]] = 1.0  # psi + b
    r = np.deg2rad(be.config.noise.ahrs_white_sigma_deg) ** 2
    k = Pa @ h / (h @ Pa @ h + r)
    Pa_after = Pa - np.outer(k, h @ Pa)
    assert be.update_heading(3.0, float(be.pose[2]) + float(rng.normal(0.0, 0.01)))
    pair = be._view_pair(cand.view)
    assert pair is not None
    np.testing.assert_allclose(pair.cov[:3, 3:], Pa_after[:3, n:], rtol=1e-9, atol=1e-15)


def test_the_distance_of_two_views_against_monte_carlo() -> None:
    """``tentative_distance`` of one line's two views, with correlated pose errors drawn from
    the pair's joint covariance: its mean is chi2(2)'s, 2 (first order; small errors)."""
    rng = np.random.default_rng(11)
    wTs_then, wTs_now = np.array([200.0, 30.0, 0.3]), np.array([202.0, 31.0, 0.32])
    A = rng.normal(size=(6, 6)) * 0.05
    common = np.diag([1.0, 1.0, 4e-4])
    cov = np.block([[common, common], [common, common]]) + A @ A.T * 0.01
    line_w = np.array([-50.0, 1.2])
    L = np.linalg.cholesky(cov)
    d2 = []
    for _ in range(1000):
        e = L @ rng.normal(size=6)
        true_now, true_then = wTs_now - e[:3], wTs_then - e[3:]
        z1 = line_world_to_frame(line_w, true_then)[0] + rng.multivariate_normal(
            np.zeros(2), R_LINE
        )
        z2 = line_world_to_frame(line_w, true_now)[0] + rng.multivariate_normal(np.zeros(2), R_LINE)
        d2.append(
            LandmarkMap.tentative_distance(z1, R_LINE, z2, R_LINE, ViewPair(wTs_now, wTs_then, cov))
        )
    assert np.mean(d2) == pytest.approx(2.0, rel=0.1)
    assert np.mean(np.asarray(d2) > 9.21) == pytest.approx(0.01, abs=0.008)
