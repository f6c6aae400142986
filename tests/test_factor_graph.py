"""The GTSAM back end: factor Jacobians on the manifold, a synthetic room, consistency, the pose
source, save/load, and a short simulated closed loop against dead reckoning."""

from __future__ import annotations

import json
from dataclasses import dataclass, replace

import gtsam
import numpy as np
import pytest
from gtsam.symbol_shorthand import B, D, G, K, L, X
from gtsam.utils.numerical_derivative import (
    numericalDerivative21,
    numericalDerivative22,
    numericalDerivative51,
    numericalDerivative52,
    numericalDerivative53,
    numericalDerivative54,
    numericalDerivative55,
)
from scipy.stats import chi2

from sonarslam.features.geometry import (
    between,
    compose,
    inverse,
    line_world_to_frame,
    transform_points,
    wrap_angle,
)
from sonarslam.features.line import LineFeature
from sonarslam.slam.backends.isam2.factors import (
    heading_factor,
    line_factor,
    noise_model,
    odometry_factor,
)
from sonarslam.slam.backends.isam2.graph import GraphConfig, LineIsam2
from sonarslam.slam.backends.isam2.graph_io import FactorKind, FactorRecord, load_graph
from sonarslam.slam.backends.isam2.pose_source import smoothed_poses
from sonarslam.slam.model.lines import (
    line_prediction,
    line_predictions,
    line_residual,
    local_to_world,
    sonar_side,
)
from sonarslam.slam.model.motion import motion_step
from sonarslam.sonar.beam import Mounting

BTS = np.array([0.3, -0.1, np.pi])  # the sonar mounting of the synthetic runs (and the sims)


def _pose2(p) -> gtsam.Pose2:
    return gtsam.Pose2(float(p[0]), float(p[1]), float(p[2]))


def _xyyaw(p: gtsam.Pose2) -> np.ndarray:
    return np.array([p.x(), p.y(), p.theta()])


# -- Jacobians ---------------------------------------------------------------------------------


def test_line_factor_jacobians_match_numerical_derivatives_on_the_manifold():
    """Both branches of the sign ambiguity, unnormalised landmarks, any mounting."""
    rng = np.random.default_rng(11)
    flipped_seen = 0
    for _ in range(300):
        wTb = _pose2([*rng.uniform(-30, 30, 2), rng.uniform(-4, 4)])
        bTs = np.array([*rng.uniform(-1, 1, 2), rng.uniform(-4, 4)])
        line_w = np.array([rng.uniform(-40, 40), rng.uniform(-7, 7)])
        z_true, _, _ = line_world_to_frame(line_w, compose(_xyyaw(wTb), bTs))
        if z_true[0] < 0.3:
            continue  # away from the normalisation's kink at rho = 0
        z = z_true + rng.normal(0.0, [0.2, 0.05])
        if rng.random() < 0.5:  # the same measured line, written the other way round
            z = np.array([-z[0], float(wrap_angle(z[1] + np.pi))])
            flipped_seen += 1
        factor = line_factor(X(0), L(0), z, np.diag([0.04, 0.003]), bTs)

        def err(p: gtsam.Pose2, lw: np.ndarray, f=factor) -> np.ndarray:
            v = gtsam.Values()
            v.insert(X(0), p)
            v.insert(L(0), lw)
            return f.unwhitenedError(v)

        e, H_pose, H_line = line_residual(z, _xyyaw(wTb), line_w, bTs)
        assert np.allclose(e, err(wTb, line_w), atol=1e-12)
        assert np.allclose(H_pose, numericalDerivative21(err, wTb, line_w, 1e-6), atol=1e-6)
        assert np.allclose(H_line, numericalDerivative22(err, wTb, line_w, 1e-6), atol=1e-6)
    assert flipped_seen > 100


def test_line_factor_passes_its_jacobians_to_gtsam_whitened():
    cov = np.array([[0.05, 0.004], [0.004, 0.002]])
    z = np.array([12.0, 0.4])
    line_w = np.array([20.0, 1.1])
    wTb = np.array([2.0, -3.0, 0.6])
    factor = line_factor(X(3), L(7), z, cov, BTS)
    values = gtsam.Values()
    values.insert(X(3), _pose2(wTb))
    values.insert(L(7), line_w)
    A, b = factor.linearize(values).jacobian()
    e, H_pose, H_line = line_residual(z, wTb, line_w, BTS)
    R_sqrt = noise_model(cov).R()  # whitening: R_sqrt^T R_sqrt = cov^-1
    assert np.allclose(A, R_sqrt @ np.hstack([H_pose, H_line]), atol=1e-9)
    assert np.allclose(b, -R_sqrt @ e, atol=1e-9)


def test_heading_and_odometry_jacobians_match_numerical_derivatives():
    rng = np.random.default_rng(5)
    for _ in range(150):
        wTi = _pose2([*rng.uniform(-30, 30, 2), rng.uniform(-4, 4)])
        wTj = _pose2([*rng.uniform(-30, 30, 2), rng.uniform(-4, 4)])
        bias = np.array([rng.uniform(-0.2, 0.2)])
        hf = heading_factor(X(0), B(0), rng.uniform(-4, 4), 0.02)

        def h_err(p, b, f=hf):
            v = gtsam.Values()
            v.insert(X(0), p)
            v.insert(B(0), b)
            return f.unwhitenedError(v)

        v = gtsam.Values()
        v.insert(X(0), wTi)
        v.insert(B(0), bias)
        A, _ = hf.linearize(v).jacobian()
        H_num = np.hstack(
            [
                numericalDerivative21(h_err, wTi, bias, 1e-6),
                numericalDerivative22(h_err, wTi, bias, 1e-6),
            ]
        )
        assert np.allclose(A * 0.02, H_num, atol=1e-6)

        # odometry with the DVL misalignment D(0), the gyro scale G(0), the DVL scale K(0)
        delta = np.array([rng.uniform(-0.3, 0.3)])
        scale = np.array([rng.uniform(0.7, 1.3)])
        dvl_k = np.array([rng.uniform(-0.05, 0.05)])
        measured = np.array([*rng.uniform(-3, 3, 2), rng.uniform(-1, 1)])
        of = odometry_factor(
            X(0),
            X(1),
            measured,
            np.eye(3),
            misalignment_key=D(0),
            scale_key=G(0),
            yaw_raw_rad=rng.uniform(-1, 1),
            d_t_d_scale=rng.uniform(-2, 2, 2),
            scale0=rng.uniform(0.8, 1.2),
            dvl_scale_key=K(0),
        )

        def o_err(a, b_, d, g, k, f=of):
            vv = gtsam.Values()
            vv.insert(X(0), a)
            vv.insert(X(1), b_)
            vv.insert(D(0), d)
            vv.insert(G(0), g)
            vv.insert(K(0), k)
            return f.unwhitenedError(vv)

        vv = gtsam.Values()
        vv.insert(X(0), wTi)
        vv.insert(X(1), wTj)
        vv.insert(D(0), delta)
        vv.insert(G(0), scale)
        vv.insert(K(0), dvl_k)
        A, _ = of.linearize(vv).jacobian()
        args = (o_err, wTi, wTj, delta, scale, dvl_k, 1e-6)
        H_num = np.hstack(
            [
                numericalDerivative51(*args),
                numericalDerivative52(*args),
                numericalDerivative53(*args),
                numericalDerivative54(*args),
                numericalDerivative55(*args),
            ]
        )
        assert np.allclose(A, H_num, atol=1e-6)


def test_odometry_agrees_with_gtsams_between_factor_without_misalignment_and_scale():
    rng = np.random.default_rng(8)
    measured = np.array([1.2, -0.4, 0.3])
    cov = np.diag([0.01, 0.02, 0.001])
    wTi = _pose2([3.0, 4.0, 1.0])
    ours = odometry_factor(X(0), X(1), measured, cov, D(0), G(0), 0.3, [0.5, -0.2], 1.0)
    theirs = gtsam.BetweenFactorPose2(X(0), X(1), _pose2(measured), noise_model(cov))
    for _ in range(20):
        wTj = wTi.compose(_pose2(measured)).retract(rng.normal(0.0, 1e-3, 3))
        v = gtsam.Values()
        v.insert(X(0), wTi)
        v.insert(X(1), wTj)
        v.insert(D(0), np.zeros(1))
        v.insert(G(0), np.ones(1))  # s = scale0: yaw = 1.0 * yaw_raw = the measured yaw
        # the same error to first order: equal up to O(|e|^2)
        assert np.allclose(ours.unwhitenedError(v), theirs.unwhitenedError(v), atol=1e-5)


def test_odometry_translation_follows_the_gyro_scale():
    """The accumulated ``d(x, y)/d(scale)`` is the derivative of the integrated arc's end."""
    from sonarslam.slam.model.motion import RelativeMotion

    def arc(scale: float) -> RelativeMotion:
        m = RelativeMotion()
        for k in range(50):
            m.step(0.05, 0.01 * np.sin(k), scale * 0.02, 0.0, 0.0, 0.02)
        return m

    base, eps = arc(1.0), 1e-6
    numerical = (arc(1.0 + eps).pose[:2] - arc(1.0 - eps).pose[:2]) / (2 * eps)
    assert np.allclose([base.jx, base.jy], numerical, atol=1e-7)
    assert base.yaw_raw == pytest.approx(1.0, rel=1e-12)


def test_vectorised_predictions_equal_the_factor_model():
    rng = np.random.default_rng(2)
    wTb = np.array([4.0, -2.0, 2.2])
    lines = np.column_stack([rng.uniform(-30, 30, 50), rng.uniform(-6, 6, 50)])
    z_hat, H_pose, H_line = line_predictions(wTb, lines, BTS)
    M = local_to_world(float(wTb[2]))
    for k in range(lines.shape[0]):
        e, Hp, Hl = line_residual(z_hat[k], wTb, lines[k], BTS)
        assert np.allclose(e, 0.0, atol=1e-12)
        assert np.allclose(-Hp, H_pose[k] @ M, atol=1e-12) and np.allclose(
            -Hl, H_line[k], atol=1e-12
        )
        z1, Hp1, Hl1 = line_prediction(wTb, lines[k], BTS)
        assert np.allclose(z1, z_hat[k], atol=1e-12)
        assert np.allclose(Hp1, H_pose[k], atol=1e-12) and np.allclose(Hl1, H_line[k], atol=1e-12)


def test_sonar_side_tells_the_two_faces_of_a_jetty_apart():
    # a jetty 3 m wide along y: faces x = 10 and x = 13, both (rho, 0) lines
    faces = np.array([[10.0, 0.0], [13.0, 0.0]])
    bTs = np.array([0.3, 0.0, np.pi])
    west = sonar_side(np.array([5.0, 2.0, 0.3]), faces, bTs)  # sonar at x = 5.3
    east = sonar_side(np.array([18.0, -4.0, 2.0]), faces, bTs)
    inside = sonar_side(np.array([11.0, 0.0, 0.0]), faces, bTs)  # sonar at x = 11.3
    assert west.tolist() == [1.0, 1.0] and east.tolist() == [-1.0, -1.0]
    assert inside.tolist() == [-1.0, 1.0]
    # the side is a property of the stored parameters: (-rho, theta + pi) is the other side
    assert sonar_side(np.array([5.0, 2.0, 0.3]), -faces + [0.0, np.pi], bTs).tolist() == [-1, -1]


# -- a synthetic room --------------------------------------------------------------------------

#: A 40 m x 24 m room: world lines (rho, theta) and their corners.
ROOM_CORNERS = np.array([[-20.0, -12.0], [20.0, -12.0], [20.0, 12.0], [-20.0, 12.0]])
WALLS = np.array([[20.0, 0.0], [12.0, np.pi / 2], [20.0, -np.pi], [12.0, -np.pi / 2]])
WALL_ENDS = [ROOM_CORNERS[[1, 2]], ROOM_CORNERS[[2, 3]], ROOM_CORNERS[[3, 0]], ROOM_CORNERS[[0, 1]]]


@dataclass
class SyntheticRun:
    backend: LineIsam2
    t_s: np.ndarray
    truth: np.ndarray  # (N, 3)
    dead_reckoning: np.ndarray  # (N, 3)
    bias_rad: float


def run_room(
    seed: int,
    duration_s: float = 120.0,
    config: GraphConfig | None = None,
    sigma_v_mps: float = 0.05,
    line_sigma: tuple[float, float] = (0.05, 0.0087),
    random_gauge: bool = False,
) -> SyntheticRun:
    """Drive a LineIsam2 through the Backend protocol around a circle in the room.

    The vehicle circles (radius 7 m, 0.5 m/s); every 0.1 s the back end predicts with a noisy
    body velocity and the true yaw rate (+ noise), every 0.1 s an AHRS heading ``yaw + b + w``
    arrives, every 2 s a vote sees the walls within 25 m with noise ``line_sigma`` (m, rad). With
    ``random_gauge`` the start pose error and the AHRS bias are drawn from the back end's
    priors (a Monte Carlo sample for consistency checks), else both are zero.
    """
    rng = np.random.default_rng(seed)
    cfg = config or GraphConfig()
    dt, radius, speed = 0.1, 7.0, 0.5
    rate = speed / radius
    t = np.arange(0.0, duration_s + 1e-9, dt)
    truth = np.column_stack(
        [radius * np.sin(rate * t), -radius * np.cos(rate * t) + 2.0, wrap_angle(rate * t)]
    )
    sigma_w = np.deg2rad(0.5)  # AHRS white noise in the data (the model says 1 deg at 1 Hz)
    P0 = np.diag([0.3**2, 0.3**2, sigma_w**2])
    bias = rng.normal(0.0, np.deg2rad(cfg.noise.ahrs_bias_sigma_deg)) if random_gauge else 0.0
    start = truth[0].copy()
    if random_gauge:
        start[:2] += rng.normal(0.0, 0.3, 2)
        start[2] += rng.normal(0.0, sigma_w)
    start[2] += bias  # the start yaw is the AHRS's
    be = LineIsam2(t[0], start, P0, Mounting(*BTS), cfg)
    dr = [start.copy()]
    p_dr = start.copy()
    R = np.diag(np.square(line_sigma))
    for k in range(1, t.size):
        v_meas = np.array([speed, 0.0]) + rng.normal(0.0, sigma_v_mps, 2)
        r_meas = rate + rng.normal(0.0, 0.002)
        be.predict(motion_step(t[k - 1], t[k], v_meas, sigma_v_mps, r_meas, t[k - 1]))
        p_dr = compose(p_dr, np.array([dt * v_meas[0], dt * v_meas[1], dt * r_meas]))
        yaw_meas = float(wrap_angle(truth[k, 2] + bias + rng.normal(0.0, sigma_w)))
        be.update_heading(t[k], yaw_meas)
        p_dr[2] = yaw_meas - 0.0  # dead reckoning takes the AHRS heading as it is
        dr.append(p_dr.copy())
        if k % 20 == 0:
            wTs = compose(truth[k], BTS)
            feats = []
            for line_w, ends in zip(WALLS, WALL_ENDS, strict=True):
                z, _, _ = line_world_to_frame(line_w, wTs)
                if z[0] > 25.0:
                    continue
                zn = z + rng.normal(0.0, line_sigma)
                ends_r = transform_points(inverse(wTs), ends)
                feats.append(LineFeature(t[k], wTs, float(zn[0]), float(zn[1]), R, 50, ends_r, 50))
            be.update_lines(feats)
    return SyntheticRun(be, t, truth, np.array(dr), bias)


@pytest.fixture(scope="module")
def room() -> SyntheticRun:
    return run_room(1)


def test_room_recovers_the_walls_and_the_trajectory(room: SyntheticRun):
    be = room.backend
    assert len(be.map) == 4  # one landmark per wall, no duplicates
    lines = be.map_records()
    for lm in lines:
        d = [abs(lm["rho"] - w[0]) + abs(float(wrap_angle(lm["theta"] - w[1]))) for w in WALLS]
        assert min(d) < 0.15  # m + rad: within 0.15 m and ~2 deg of a true wall
        # a vote per metre of the 60 m path, a view counted once the vehicle moved 5 m since
        # the landmark's last one (reobservation_min_move_m): 8-12 per wall on this seed
        assert lm["observations"] >= 6
    sm = be.smoothed_trajectory(covariances=True)
    truth = np.interp(sm.t_s, room.t_s, np.arange(room.t_s.size))
    true_poses = room.truth[np.round(truth).astype(int)]
    err_xy = np.hypot(*(sm.poses_wTb[:, :2] - true_poses[:, :2]).T)
    err_yaw = np.abs(wrap_angle(sm.poses_wTb[:, 2] - true_poses[:, 2]))
    dr_xy = np.hypot(*(room.dead_reckoning[:, :2] - room.truth[:, :2]).T)
    assert err_xy.max() < 0.25 and np.rad2deg(err_yaw.max()) < 1.0
    assert err_xy.mean() < 0.5 * dr_xy.mean()  # the walls beat dead reckoning
    assert be.stats["associated"] >= 0.9 * be.stats["observations"] - 8


def test_room_batch_lm_agrees_with_isam2(room: SyntheticRun):
    be = room.backend
    isam_values = be.isam.calculateEstimate()
    batch = be.optimize_batch()
    assert be.graph.error(batch) <= be.graph.error(isam_values) + 1e-9
    for k in range(be.n_nodes):
        a, b = _xyyaw(isam_values.atPose2(X(k))), _xyyaw(batch.atPose2(X(k)))
        # iSAM2 takes one Gauss-Newton step per update (the Huber weights lag a step)
        assert np.hypot(*(a[:2] - b[:2])) < 0.05 and abs(wrap_angle(a[2] - b[2])) < 3e-3


def test_room_lines_re_decided_keep_the_walls_and_the_trajectory(room: SyntheticRun):
    """The lines re-decided at the smoothed estimate (straight walls of 24-40 m: one stretch
    each, no observation moved) give the smoothed estimate's accuracy; the estimate is among
    the trajectories only when ``redecide_stretch_m`` is set, and the graph is left as it was."""
    be = room.backend
    n_records = len(be.records)
    out = be.redecide_lines()
    m = out.metrics()
    assert m["redecided_stretches"] == 4 and m["redecided_moved"] == 0
    assert m["redecided_dropped"] <= 2
    tr = be.redecided_trajectory()
    index = np.round(np.interp(tr.t_s, room.t_s, np.arange(room.t_s.size))).astype(int)
    err_xy = np.hypot(*(tr.poses_wTb[:, :2] - room.truth[index, :2]).T)
    assert err_xy.max() < 0.25
    assert len(be.records) == n_records and m.items() <= be.metrics().items()
    assert "redecided" not in be.trajectories()
    config = be.config
    try:
        be.config = replace(config, redecide_stretch_m=30.0)
        assert len(be.trajectories()["redecided"].t_s) == be.n_nodes
        assert be.metrics()["redecided_stretches"] >= 4
    finally:
        be.config = config


def test_the_ahrs_bias_is_unobservable_so_its_prior_alone_fixes_it(room: SyntheticRun):
    """Rotating poses and walls about the start position while the bias takes the rotation
    back leaves every factor unchanged but the bias prior: line landmarks, DVL, gyro and the
    start position cannot see the bias, which is why no back end can undo a biased compass's
    rotation of the whole run."""
    be = room.backend
    values = be.isam.calculateEstimate()
    alpha = 0.05
    c, s = np.cos(alpha), np.sin(alpha)
    p0 = _xyyaw(values.atPose2(X(0)))[:2]
    rotated = gtsam.Values()
    for key in values.keys():
        sym = gtsam.Symbol(key)
        if sym.chr() == ord("x"):
            p = _xyyaw(values.atPose2(key))
            xy = p0 + np.array([[c, -s], [s, c]]) @ (p[:2] - p0)
            rotated.insert(key, gtsam.Pose2(xy[0], xy[1], p[2] + alpha))
        elif sym.chr() == ord("l"):
            rho, theta = values.atVector(key)
            n0 = np.array([np.cos(theta), np.sin(theta)])
            n1 = np.array([np.cos(theta + alpha), np.sin(theta + alpha)])
            rotated.insert(key, np.array([rho - p0 @ n0 + p0 @ n1, theta + alpha]))
        elif sym.chr() == ord("b"):
            rotated.insert(key, values.atVector(key) - alpha)
        else:  # the sonar's mounting and range scale are the body's: a rotation leaves them
            rotated.insert(key, values.atVector(key))
    for i, record in enumerate(be.records):
        e0, e1 = be.graph.at(i).error(values), be.graph.at(i).error(rotated)
        if record.kind is FactorKind.PRIOR_VECTOR and record.keys[0] == B(0):
            assert (
                e1
                > e0 + 0.5 * (alpha / np.deg2rad(be.config.noise.ahrs_bias_sigma_deg)) ** 2 - 1e-6
            )
            continue
        assert e1 == pytest.approx(e0, rel=1e-6, abs=1e-9)
    sigma_b = np.sqrt(be.isam.marginalCovariance(B(0))[0, 0])
    assert sigma_b == pytest.approx(np.deg2rad(be.config.noise.ahrs_bias_sigma_deg), rel=0.01)


def test_pose_covariance_is_consistent_over_monte_carlo_runs():
    """Start pose and AHRS bias drawn from the priors: the mean NEES of the final smoothed pose
    over the runs lies in the two-sided 95 % band of chi2(3 n) / n."""
    n = 16
    nees = []
    for seed in range(n):
        run = run_room(100 + seed, duration_s=60.0, random_gauge=True)
        tr = run.backend.smoothed_trajectory(covariances=True)
        k = int(np.argmin(np.abs(run.t_s - tr.t_s[-1])))
        e = tr.poses_wTb[-1] - run.truth[k]
        e[2] = wrap_angle(e[2])
        nees.append(float(e @ np.linalg.solve(tr.covs[-1], e)))
    lo, hi = chi2.ppf([0.025, 0.975], 3 * n) / n
    assert lo <= np.mean(nees) <= hi, (np.mean(nees), lo, hi)


def test_online_pose_and_covariance_follow_the_newest_node(room: SyntheticRun):
    be = room.backend
    sm = be.smoothed_trajectory()
    src = be.pose_source()
    assert np.allclose(src.poses([be.t_s])[0], be.pose, atol=1e-9)
    assert np.allclose(src.covariance(be.t_s), be.pose_cov, atol=1e-12)
    assert np.allclose(src.poses(sm.t_s), sm.poses_wTb, atol=1e-9)  # through every node
    C = be.pose_cov
    assert np.allclose(C, C.T) and np.all(np.linalg.eigvalsh(C) > 0.0)


def test_between_nodes_the_pose_is_the_ekf_prediction():
    """One motion model: before the first node after X(0) the graph's current pose and
    covariance are X(0)'s marginal propagated by the same motion steps as the EKF's prediction
    (one held DVL sample over several steps included)."""
    from sonarslam.slam.backends.ekf import POSE, EkfConfig, LineEkf
    from sonarslam.slam.model.motion import motion_step

    rng = np.random.default_rng(21)
    cfg = GraphConfig()
    wTb0 = np.array([3.0, -1.0, 0.4])
    P0 = np.array([[0.5, 0.1, 0.0], [0.1, 0.3, 0.0], [0.0, 0.0, 0.01]])
    be = LineIsam2(100.0, wTb0, P0, Mounting(*BTS), cfg)
    ekf = LineEkf(100.0, wTb0, P0, Mounting(*BTS), EkfConfig())
    # X(0)'s marginal: the prior's position, the AHRS start heading (its white noise as the
    # back ends model it, not P0's) plus the bias prior
    P = P0.copy()
    P[2, 2] = (
        np.deg2rad(cfg.noise.ahrs_white_sigma_deg) ** 2
        + np.deg2rad(cfg.noise.ahrs_bias_sigma_deg) ** 2
    )
    assert np.allclose(be.pose_cov, P, atol=1e-9)
    assert np.allclose(ekf.P[POSE, POSE], P, atol=1e-12)
    t, held_from = 100.0, 100.0
    v = rng.normal(0.0, 0.5, 2)
    for k in range(40):  # 4 s < node_period_s: no node, no update
        dt = rng.uniform(0.05, 0.15)
        if k % 5 == 0:  # a new DVL sample every fifth step
            v, held_from = rng.normal(0.0, 0.5, 2), t
        step = motion_step(t, t + dt, v, 0.05, rng.normal(0.0, 0.1), held_from)
        t += dt
        np.testing.assert_allclose(be.predict(step), ekf.predict(step), atol=1e-15)
    assert be.n_nodes == 1
    assert np.allclose(be.pose[:2], ekf.pose[:2], atol=1e-9)
    assert abs(wrap_angle(be.pose[2] - ekf.pose[2])) < 1e-9
    assert np.allclose(be.pose_cov, ekf.pose_cov, atol=1e-9)


# -- the pose source ---------------------------------------------------------------------------


def test_the_odometry_chain_interpolates_its_steps_and_holds_past_its_ends():
    from sonarslam.slam.model.motion import OdometryChain

    chain = OdometryChain(0.0, capacity=2)  # forces buffer growth
    for k in range(1, 50):
        chain.append(0.1 * k, np.array([0.1, 0.0, 0.02]), 0.001)
    assert len(chain) == 50
    odo = chain.at(chain.t_s)
    np.testing.assert_allclose(odo[1], [0.1, 0.0, 0.02], atol=1e-12)
    mid = chain.at([0.15])[0]
    np.testing.assert_allclose(mid, 0.5 * (odo[1] + odo[2]), atol=1e-12)
    np.testing.assert_allclose(chain.at([-5.0, 99.0]), odo[[0, -1]], atol=1e-12)
    assert chain.variance_at(0.25) == pytest.approx(0.0025, rel=1e-9)
    np.testing.assert_allclose(chain.now, odo[-1], atol=1e-12)
    chain.append(4.9, np.zeros(3))  # records may share a time: a step of zero
    assert chain.variance_at(4.9) == pytest.approx(0.049, rel=1e-9)
    np.testing.assert_allclose(chain.at([4.9])[0], odo[-1], atol=1e-12)


def test_smoothed_poses_pass_through_nodes_and_follow_the_odometry():
    # odometry: a constant-rate arc, sampled every 0.1 s, in its own frame
    t = np.arange(0.0, 10.0 + 1e-9, 0.1)
    odo = np.column_stack([np.sin(0.2 * t) / 0.2, (1 - np.cos(0.2 * t)) / 0.2, 0.2 * t])
    node_idx = np.array([0, 40, 70])
    node_t = t[node_idx]
    wTo = np.array([5.0, -3.0, 0.7])  # the world pose of the odometry frame
    agree = compose(wTo, odo[node_idx])
    # 1. nodes that agree with the odometry: the pose source is the odometry itself
    out = smoothed_poses(t, node_t, agree, odo[node_idx], odo)
    expected = compose(wTo, odo)
    assert np.allclose(out[:, :2], expected[:, :2], atol=1e-9)
    assert np.allclose(wrap_angle(out[:, 2] - expected[:, 2]), 0.0, atol=1e-9)
    # 2. nodes moved by the smoother: through each node, the correction blended in between
    shift = np.array([[0.0, 0.0, 0.0], [0.4, -0.2, 0.02], [1.0, 0.3, -0.03]])
    nodes = agree + shift
    out = smoothed_poses(t, node_t, nodes, odo[node_idx], odo)
    assert np.allclose(out[node_idx], nodes, atol=1e-9)
    mid = 55  # 15/30 of the way from node 1 to node 2
    carried_1 = compose(nodes[1], between(odo[40], odo[mid]))
    carried_2 = compose(nodes[2], between(odo[70], odo[mid]))
    blend = carried_1 + 0.5 * (carried_2 - carried_1)
    assert np.allclose(out[mid], blend, atol=1e-9)
    # 3. past the newest node: that node carried by the odometry
    late = smoothed_poses([9.5], node_t, nodes, odo[node_idx], odo[[95]])[0]
    assert np.allclose(late, compose(nodes[2], between(odo[70], odo[95])), atol=1e-9)


# -- save / load -------------------------------------------------------------------------------


def test_save_and_load_round_trip(room: SyntheticRun, tmp_path):
    be = room.backend
    (path,) = be.save(tmp_path)
    assert path == tmp_path / "graph.json"
    graph, values = load_graph(path)
    original = be.estimate()
    assert graph.size() == be.graph.size() == len(be.records)
    assert values.size() == original.size()
    assert graph.error(values) == pytest.approx(be.graph.error(original), rel=1e-12)
    # same factors: same linear system at the same point
    A0, b0 = be.graph.linearize(original).jacobian()
    A1, b1 = graph.linearize(values).jacobian()
    assert np.allclose(A0, A1, atol=1e-12) and np.allclose(b0, b1, atol=1e-12)
    # and a GTSAM user can optimise it
    result = gtsam.LevenbergMarquardtOptimizer(graph, values).optimize()
    assert graph.error(result) <= graph.error(values) + 1e-9


def test_robust_kernel_downweights_a_wrong_line():
    cov = np.diag([0.01, 1e-4])
    z = np.array([10.0, 0.0])
    values = gtsam.Values()
    values.insert(X(0), gtsam.Pose2())
    values.insert(L(0), np.array([10.0 + 3.0, np.pi]))  # sonar yaw pi: z_hat = (13, 0)
    plain = line_factor(X(0), L(0), z, cov, np.array([0.0, 0.0, np.pi]))
    huber = line_factor(X(0), L(0), z, cov, np.array([0.0, 0.0, np.pi]), robust="huber")
    assert plain.error(values) == pytest.approx(0.5 * 9.0 / 0.01, rel=1e-9)
    r, k = 30.0, 1.345  # whitened residual (3 m / 0.1 m), Huber width
    assert huber.error(values) == pytest.approx(k * r - 0.5 * k * k, rel=1e-6)
    with pytest.raises(ValueError, match="robust"):
        GraphConfig(robust="tukey")


# -- a simulated harbour in closed loop ----------------------------------------------------------


def test_short_simulated_closed_loop_beats_dead_reckoning(tmp_path_factory):
    """300 s of harbour with a poor DVL (0.1 m/s, a dropout every 30 s) and no AHRS bias, so
    that drift, not the unobservable gauge, dominates the dead reckoning error."""
    from sonarslam.datasets.simulator import make_scenario, simulate_records
    from sonarslam.datasets.simulator.writer import write_dataset
    from sonarslam.datasets.source import open_dataset
    from sonarslam.features.config import ExtractorConfig
    from sonarslam.slam.eval.ate import ate_against_gps
    from sonarslam.slam.eval.truth import (
        association_against_truth,
        landmark_overshoot_m,
        truth_trajectory,
        truth_walls,
    )
    from sonarslam.slam.run.closed_loop import run_closed_loop
    from sonarslam.slam.run.sources import dead_reckoning_trajectory

    scenario = make_scenario("harbour", 3, 300.0)
    noise = replace(
        scenario.noise, ahrs_bias_deg=0.0, dvl_sigma_mps=0.1, dvl_dropout_rate_per_s=1 / 30
    )
    root = write_dataset(
        simulate_records(replace(scenario, noise=noise)), tmp_path_factory.mktemp("h3")
    )
    dataset = open_dataset(root)
    result = run_closed_loop(
        dataset,
        lambda t, p, c: LineIsam2(t, p, c, dataset.config.sonar_mounting, GraphConfig()),
        ExtractorConfig(),
        progress=False,
    )
    span = result.trajectory.span_s
    dr = dead_reckoning_trajectory(dataset).clip(*span)
    ate_dr = ate_against_gps(dr, dataset.gps).ate_mean_m
    ate_online = ate_against_gps(result.trajectory, dataset.gps).ate_mean_m
    smoothed = result.backend.smoothed_trajectory(covariances=True)
    ate_smoothed = ate_against_gps(smoothed, dataset.gps).ate_mean_m
    assert ate_online < 0.85 * ate_dr and ate_smoothed < 0.85 * ate_dr
    truth = truth_trajectory(dataset).poses(smoothed.t_s)
    e = smoothed.poses_wTb - truth
    e[:, 2] = wrap_angle(e[:, 2])
    anees = np.mean(np.einsum("ni,nij,nj->n", e, np.linalg.inv(smoothed.covs), e))
    assert 0.3 < anees < 6.0  # one run: its samples are correlated in time, the band is loose
    assert result.backend.stats["associated"] >= 0.4 * result.backend.stats["observations"]
    # association against the true walls: the targets (precision 99 %, recall 95 %)
    walls = truth_walls(dataset)
    scores = association_against_truth(
        dataset, result.features, result.feature_landmarks, result.feature_seeds
    )
    assert scores.n_associated >= 20 and scores.n_seeds >= 1
    assert scores.precision >= 0.99 and scores.recall >= 0.95
    assert scores.seed_precision == 1.0
    # every landmark's extent stays on its walls (2 m of pose error, margin of the extent gate)
    overshoot = landmark_overshoot_m(result.backend.map_records(), walls)
    assert overshoot.max() < 12.0, overshoot


def test_every_factor_kind_round_trips_through_its_json_form(room: SyntheticRun):
    """Each record the graph made reads back to the same record, which builds a factor with the
    same error at the estimate."""
    be = room.backend
    values = be.estimate()
    kinds = set()
    for record in be.records:
        again = FactorRecord.from_json(json.loads(json.dumps(record.to_json())))
        assert again.to_json() == record.to_json()
        e0, e1 = record.to_gtsam().error(values), again.to_gtsam().error(values)
        assert e1 == pytest.approx(e0, rel=1e-12, abs=1e-12)
        kinds.add(record.kind)
    assert FactorKind.HEADING_BIAS in kinds
    assert kinds & {FactorKind.LINE_OBSERVATION, FactorKind.LINE_OBSERVATION_CALIBRATED}


@pytest.mark.parametrize(
    "change,message",
    [
        ({"type": "Teleport"}, "'Teleport' is not a valid FactorKind"),
        ({"covariance": [[1.0]]}, "covariance (1, 1) does not match"),
        ({"keys": ["x0"]}, "takes 2 keys, got 1"),
        ({"measurement": [1.0, 2.0, 3.0], "covariance": np.eye(3).tolist()}, "expected 2"),
        ({"bTs": [0.1, 0.2]}, "bTs of shape (2,), expected (3,)"),
        ({"robust": {"kernel": "tukey", "k": 1.0}}, "robust kernel 'tukey'"),
    ],
)
def test_load_graph_names_the_file_and_the_factor_it_cannot_read(
    room: SyntheticRun, tmp_path, change: dict, message: str
):
    (path,) = room.backend.save(tmp_path)
    doc = json.loads(path.read_text())
    i = next(i for i, f in enumerate(doc["factors"]) if f["type"] == "LineObservation")
    doc["factors"][i] |= change
    path.write_text(json.dumps(doc))
    with pytest.raises(ValueError, match=f"graph.json: factor {i}: ") as err:
        load_graph(path)
    assert message in str(err.value)


def test_load_graph_names_a_factor_that_is_not_an_object(room: SyntheticRun, tmp_path):
    (path,) = room.backend.save(tmp_path)
    doc = json.loads(path.read_text())
    doc["factors"][3] = ["PriorFactorPose2"]
    path.write_text(json.dumps(doc))
    with pytest.raises(ValueError, match="graph.json: factor 3: a factor is a JSON object"):
        load_graph(path)
