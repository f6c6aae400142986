"""The sonar's calibration as state (:mod:`sonarslam.slam.model.calibration`): the mounting
``C(0)`` and range scale ``R(0)`` in the line and scan factors. Jacobians against numerical
derivatives on the manifold; the models against a sonar that sees points (a line fitted to a
scaled wall, a rigid registration of two scaled scans); recovery in a small graph."""

from __future__ import annotations

import gtsam
import numpy as np
from gtsam.symbol_shorthand import C, L, R, X
from gtsam.utils.numerical_derivative import (
    numericalDerivative41,
    numericalDerivative42,
    numericalDerivative43,
    numericalDerivative44,
)

from sonarslam.features.geometry import (
    between,
    compose,
    inverse,
    line_world_to_frame,
    transform_points,
    wrap_angle,
)
from sonarslam.slam.backends.isam2.factors import calibrated_line_factor, calibrated_scan_factor
from sonarslam.slam.backends.isam2.graph_io import FactorKind, FactorRecord
from sonarslam.slam.model.calibration import (
    line_residual_calibrated,
    scan_prediction,
    scan_residual,
)
from sonarslam.slam.model.lines import line_residual


def _pose2(p) -> gtsam.Pose2:
    return gtsam.Pose2(float(p[0]), float(p[1]), float(p[2]))


def _xyyaw(p: gtsam.Pose2) -> np.ndarray:
    return np.array([p.x(), p.y(), p.theta()])


def _numerical(factor: gtsam.CustomFactor, keys, args) -> np.ndarray:
    """``d error / d (each variable)`` by GTSAM's central differences (poses on the manifold)."""

    def err(a, b, c, d):
        v = gtsam.Values()
        for key, val in zip(keys, (a, b, c, d), strict=True):
            v.insert(key, val)
        return factor.unwhitenedError(v)

    fns = (numericalDerivative41, numericalDerivative42, numericalDerivative43)
    fns += (numericalDerivative44,)
    return np.hstack([f(err, *args, 1e-6) for f in fns])


def test_calibrated_line_factor_jacobians_match_numerical_derivatives():
    rng = np.random.default_rng(21)
    flipped = 0
    for _ in range(40):
        wTk = _pose2([*rng.uniform(-30, 30, 2), rng.uniform(-4, 4)])
        kTb = np.array([*rng.uniform(-1, 1, 2), rng.uniform(-0.3, 0.3)])
        mount = np.array([*rng.uniform(-1, 1, 2), rng.uniform(-4, 4)])
        scale = np.array([rng.uniform(0.9, 1.1)])
        line_w = np.array([rng.uniform(-40, 40), rng.uniform(-7, 7)])
        wTs = compose(compose(_xyyaw(wTk), kTb), mount)
        z_true, _, _ = line_world_to_frame(line_w, wTs)
        if z_true[0] < 0.3:
            continue
        z = z_true + rng.normal(0.0, [0.2, 0.05])
        if rng.random() < 0.5:
            z = np.array([-z[0], float(wrap_angle(z[1] + np.pi))])
            flipped += 1
        f = calibrated_line_factor(
            X(0), L(0), z, np.diag([0.04, 0.003]), kTb, np.zeros(3), C(0), R(0)
        )
        keys = (X(0), L(0), C(0), R(0))
        v = gtsam.Values()
        for key, val in zip(keys, (wTk, line_w, mount, scale), strict=True):
            v.insert(key, val)
        e, *H = line_residual_calibrated(z, _xyyaw(wTk), line_w, kTb, mount, float(scale[0]))
        assert np.allclose(e, f.unwhitenedError(v), atol=1e-12)
        H_num = _numerical(f, keys, (wTk, line_w, mount, scale))
        assert np.allclose(np.hstack(H), H_num, atol=1e-6)
        A, _ = f.linearize(v).jacobian()  # the same, whitened, through GTSAM
        R_sqrt = gtsam.noiseModel.Gaussian.Covariance(np.diag([0.04, 0.003])).R()
        assert np.allclose(A, R_sqrt @ H_num, atol=1e-5)
    assert flipped > 8


def test_calibrated_line_residual_is_the_plain_one_at_the_prior():
    rng = np.random.default_rng(2)
    for _ in range(50):
        wTb = np.array([*rng.uniform(-20, 20, 2), rng.uniform(-3, 3)])
        bTs = np.array([0.3, -0.1, np.pi])
        line_w = np.array([rng.uniform(5, 40), rng.uniform(-3, 3)])
        z = line_world_to_frame(line_w, compose(wTb, bTs))[0] + rng.normal(0, [0.1, 0.02])
        ours = line_residual_calibrated(z, wTb, line_w, np.zeros(3), bTs, 1.0)
        plain = line_residual(z, wTb, line_w, bTs)
        for a, b in zip(ours[:3], plain, strict=True):
            assert np.allclose(a, b, atol=1e-12)


def test_a_wall_seen_with_scaled_ranges_is_the_line_model():
    """Points of a wall logged at ``s`` times their range, fitted by total least squares,
    give ``(s * rho, theta)`` in the sonar frame: the prediction the factor compares with."""
    rng = np.random.default_rng(3)
    for _ in range(20):
        s = rng.uniform(0.95, 1.05)
        wTs = np.array([*rng.uniform(-5, 5, 2), rng.uniform(-3, 3)])
        line_w = np.array([rng.uniform(10, 30), rng.uniform(-3, 3)])
        z, _, _ = line_world_to_frame(line_w, wTs)
        n = np.array([np.cos(z[1]), np.sin(z[1])])
        pts = z[0] * n + np.outer(rng.uniform(-15, 15, 40), [-n[1], n[0]])  # sonar frame
        seen = s * pts
        centre = seen.mean(axis=0)
        _, _, vt = np.linalg.svd(seen - centre)
        normal = vt[-1] * np.sign(vt[-1] @ centre)
        rho, theta = float(normal @ centre), float(np.arctan2(normal[1], normal[0]))
        assert abs(rho - s * z[0]) < 1e-9
        assert abs(wrap_angle(theta - z[1])) < 1e-9


def test_calibrated_scan_factor_jacobians_match_numerical_derivatives():
    rng = np.random.default_rng(22)
    for _ in range(40):
        wTi = _pose2([*rng.uniform(-30, 30, 2), rng.uniform(-4, 4)])
        wTj = wTi.compose(_pose2([*rng.uniform(-5, 5, 2), rng.uniform(-1, 1)]))
        a = np.array([*rng.uniform(-1, 1, 2), rng.uniform(-4, 4)])
        mount = a + np.array([*rng.normal(0, 0.2, 2), rng.normal(0, 0.05)])
        scale = np.array([rng.uniform(0.9, 1.1)])
        z = _xyyaw(wTi.between(wTj)) + rng.normal(0.0, [0.2, 0.2, 0.03])
        f = calibrated_scan_factor(X(0), X(1), z, np.eye(3), a, C(0), R(0))
        keys = (X(0), X(1), C(0), R(0))
        v = gtsam.Values()
        for key, val in zip(keys, (wTi, wTj, mount, scale), strict=True):
            v.insert(key, val)
        e, *H = scan_residual(z, _xyyaw(wTi), _xyyaw(wTj), mount, float(scale[0]), a)
        assert np.allclose(e, f.unwhitenedError(v), atol=1e-12)
        assert np.allclose(np.hstack(H), _numerical(f, keys, (wTi, wTj, mount, scale)), atol=1e-6)


def test_the_scan_model_is_a_registration_of_scaled_scans():
    """Two scans of the same world points, seen from a sonar at ``bTs`` with ranges scaled by
    ``s`` and put in the body frame with the assumed mounting ``a``: the rigid transform that
    registers them (Kabsch, exact correspondences) is :func:`scan_prediction`; at the prior
    (``bTs = a``, ``s = 1``) it is the body motion."""
    rng = np.random.default_rng(4)
    world = rng.uniform(-20, 20, (60, 2))
    for _ in range(20):
        a = np.array([0.3, 0.0, np.pi])
        bTs = a + np.array([*rng.uniform(-0.2, 0.2, 2), np.deg2rad(rng.uniform(-0.5, 0.5))])
        s = rng.uniform(0.96, 1.04)
        wTi = np.array([*rng.uniform(-3, 3, 2), rng.uniform(-3, 3)])
        wTj = compose(wTi, np.array([*rng.uniform(-2, 2, 2), rng.uniform(-0.5, 0.5)]))

        def scan(wTb, bTs=bTs, s=s, a=a):
            in_sonar = transform_points(inverse(compose(wTb, bTs)), world)
            return transform_points(a, s * in_sonar)  # the body frame, through a

        P, Q = scan(wTi), scan(wTj)  # P = T Q
        pc, qc = P.mean(axis=0), Q.mean(axis=0)
        U, _, Vt = np.linalg.svd((Q - qc).T @ (P - pc))
        Rm = (U @ Vt).T
        t = pc - Rm @ qc
        T = np.array([t[0], t[1], np.arctan2(Rm[1, 0], Rm[0, 0])])
        h = scan_prediction(between(wTi, wTj), bTs, s, a)[0]
        assert np.allclose(T[:2], h[:2], atol=1e-9)
        assert abs(wrap_angle(T[2] - h[2])) < 1e-9
        h0 = scan_prediction(between(wTi, wTj), a, 1.0, a)[0]
        assert np.allclose(h0[:2], between(wTi, wTj)[:2], atol=1e-12)


def test_calibrated_records_round_trip_through_json():
    line = FactorRecord.of(
        FactorKind.LINE_OBSERVATION_CALIBRATED,
        [X(3), L(2), C(0), R(0)],
        [12.0, 0.3],
        np.diag([0.04, 0.002]),
        bTs=np.array([0.3, 0.0, np.pi]),
        kTb=np.array([0.1, 0.0, 0.01]),
    )
    scan = FactorRecord.of(
        FactorKind.SCAN_CALIBRATED,
        [X(3), X(4), R(0)],
        [1.0, 0.2, 0.1],
        np.eye(3) * 0.01,
        bTs=np.array([0.3, 0.0, np.pi]),
        constraint="scan-consecutive",
    )
    v = gtsam.Values()
    v.insert(X(3), _pose2([1.0, 2.0, 0.3]))
    v.insert(X(4), _pose2([2.0, 2.1, 0.4]))
    v.insert(L(2), np.array([15.0, 0.5]))
    v.insert(C(0), np.array([0.3, 0.0, np.pi]))
    v.insert(R(0), np.array([1.02]))
    for rec in (line, scan):
        back = FactorRecord.from_json(rec.to_json())
        assert back.keys == rec.keys
        assert np.allclose(back.to_gtsam().unwhitenedError(v), rec.to_gtsam().unwhitenedError(v))


def test_the_heading_error_track_round_trips_and_names_a_bad_line(tmp_path):
    import pytest

    from sonarslam.datasets.errors import DataError
    from sonarslam.slam.io.states import read_heading_error, write_heading_error

    t = 1.7e9 + np.arange(5.0)
    b = np.deg2rad([0.1, -0.2, 0.3, 1.0, 2.0])
    sd = np.deg2rad([2.0, 1.9, 1.8, 1.7, 1.6])
    path = write_heading_error(tmp_path / "heading_error.csv", t, b, sd)
    t2, b2, sd2 = read_heading_error(path)
    assert (
        np.allclose(t2, t) and np.allclose(b2, np.rad2deg(b)) and np.allclose(sd2, np.rad2deg(sd))
    )
    text = path.read_text().splitlines()
    text[3] = "1700000002.0,abc,1.0"
    path.write_text("\n".join(text) + "\n")
    with pytest.raises(DataError, match=r"heading_error.csv.*4"):
        read_heading_error(path)
