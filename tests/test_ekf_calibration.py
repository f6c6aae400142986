"""The EKF's sonar calibration states (``ekf.estimate_sonar_mount``, ``ekf.range_scale_sigma``):
the shared calibrated line model's Jacobians (:func:`line_prediction_calibrated`,
:func:`world_line_calibrated`) and the filter's assembled line Jacobian against central
differences; a new landmark's covariance as the first-order image of the state's; and on a
seeded drawn world with a mounting offset and a range-scale error, the final estimates within
2 sigma of the simulator's truth."""

from __future__ import annotations

import numpy as np
import pytest

from sonarslam.features.geometry import line_difference, normalize_line
from sonarslam.features.line import LineFeature
from sonarslam.slam.backends.ekf import N_VEHICLE, POSE, EkfConfig, LineEkf, _filter
from sonarslam.slam.model.calibration import line_prediction_calibrated, world_line_calibrated
from sonarslam.slam.model.lines import line_prediction
from sonarslam.sonar.beam import Mounting

EPS = 1e-6


def _numerical(f, x0: np.ndarray) -> np.ndarray:
    """Central differences of ``f`` (returning (m,)) at ``x0`` (n,): (m, n)."""
    x0 = np.asarray(x0, dtype=np.float64)
    cols = []
    for j in range(x0.size):
        d = np.zeros_like(x0)
        d[j] = EPS
        cols.append((np.asarray(f(x0 + d)) - np.asarray(f(x0 - d))) / (2 * EPS))
    return np.column_stack(cols)


def _draws(rng: np.random.Generator):
    """A body pose, a world line at least 3 m from the sonar, a mounting and a range scale."""
    while True:
        wTb = np.array([rng.uniform(-20, 20), rng.uniform(-20, 20), rng.uniform(-np.pi, np.pi)])
        bTs = np.array([rng.uniform(-0.5, 0.5), rng.uniform(-0.3, 0.3), rng.uniform(2.5, 3.5)])
        line = np.array([rng.uniform(0, 40), rng.uniform(-np.pi, np.pi)])
        s = rng.uniform(0.95, 1.05)
        if line_prediction(wTb, line, bTs)[0][0] > 3.0:
            return wTb, line, bTs, s


def test_calibrated_line_prediction_jacobians_match_central_differences():
    rng = np.random.default_rng(5)
    for _ in range(40):
        _check_prediction(*_draws(rng))


def _check_prediction(wTb: np.ndarray, line: np.ndarray, bTs: np.ndarray, s: float) -> None:
    z, H_pose, H_line, H_mount, H_scale = line_prediction_calibrated(wTb, line, bTs, s)
    np.testing.assert_allclose(
        _numerical(lambda p: line_prediction_calibrated(p, line, bTs, s)[0], wTb),
        H_pose,
        atol=1e-6,
    )
    np.testing.assert_allclose(
        _numerical(lambda v: line_prediction_calibrated(wTb, v, bTs, s)[0], line),
        H_line,
        atol=1e-6,
    )
    np.testing.assert_allclose(
        _numerical(lambda m: line_prediction_calibrated(wTb, line, m, s)[0], bTs),
        H_mount,
        atol=1e-6,
    )
    np.testing.assert_allclose(
        _numerical(lambda k: line_prediction_calibrated(wTb, line, bTs, k[0])[0], [s]),
        H_scale,
        atol=1e-6,
    )
    # at scale 1 it is the uncalibrated model; the scale multiplies rho only
    z1 = line_prediction(wTb, line, bTs)[0]
    np.testing.assert_allclose(line_prediction_calibrated(wTb, line, bTs, 1.0)[0], z1)
    np.testing.assert_allclose(z, [s * z1[0], z1[1]], atol=1e-12)


def test_calibrated_world_line_inverts_the_prediction_and_its_jacobians_match():
    rng = np.random.default_rng(6)
    for _ in range(40):
        _check_world_line(*_draws(rng))


def _check_world_line(wTb: np.ndarray, line: np.ndarray, bTs: np.ndarray, s: float) -> None:
    z = line_prediction_calibrated(wTb, line, bTs, s)[0]
    line_w, G_z, G_pose, G_mount, G_scale = world_line_calibrated(z, wTb, bTs, s)
    nu, _ = line_difference(line_w, np.array(normalize_line(*line)))
    np.testing.assert_allclose(nu, 0.0, atol=1e-9)
    for G, f, x0 in (
        (G_z, lambda v: world_line_calibrated(v, wTb, bTs, s)[0], z),
        (G_pose, lambda p: world_line_calibrated(z, p, bTs, s)[0], wTb),
        (G_mount, lambda m: world_line_calibrated(z, wTb, m, s)[0], bTs),
        (G_scale, lambda k: world_line_calibrated(z, wTb, bTs, k[0])[0], np.array([s])),
    ):
        np.testing.assert_allclose(_numerical(f, x0), G, atol=1e-6)


def _ekf(**kw) -> LineEkf:
    cfg = EkfConfig(estimate_sonar_mount=True, range_scale_sigma=0.04, **kw)
    mounting = Mounting(x_m=0.3, y_m=-0.1, yaw_rad=3.0)
    return LineEkf(0.0, np.array([1.0, 2.0, 0.4]), np.eye(3) * 0.1, mounting, cfg)


def test_the_ekf_line_jacobian_over_the_whole_state_matches_central_differences():
    """``predict_line``'s H (no FEJ: at the current state) against the prediction's central
    differences in every state, calibration and landmark included."""
    ekf = _ekf(first_estimates_jacobians=False)
    cal = ekf.calibration_index()
    assert cal.mount == slice(N_VEHICLE, N_VEHICLE + 3) and cal.scale == N_VEHICLE + 3
    x = ekf.x.copy()
    x[cal.mount] += [0.05, -0.04, 0.01]  # off the prior mean
    x[cal.scale] = 1.03
    line = np.array([12.0, 0.7])
    n = x.size
    ekf.kf = _filter(np.concatenate([x, line]), np.eye(n + 2))
    ekf._index[0] = n
    ekf._first_line_w[0] = line.copy()
    z_hat, H = ekf.predict_line(0)

    def predict(state: np.ndarray) -> np.ndarray:
        ekf.kf.x = state.copy()
        return ekf.predict_line(0)[0]

    x_full = np.concatenate([x, line])
    np.testing.assert_allclose(_numerical(predict, x_full), H, atol=1e-6)
    assert np.any(H[:, cal.mount] != 0.0) and H[0, cal.scale] != 0.0


def test_a_new_landmark_takes_the_calibration_into_its_covariance():
    """The augmented covariance is ``G P G^T + G_z R G_z^T`` with ``G`` the world line's
    Jacobian in every vehicle state (the mounting's and the scale's columns included)."""
    ekf = _ekf()
    cal = ekf.calibration_index()
    P0 = ekf.P.copy()
    z = np.array([8.0, 0.3])
    cov = np.diag([0.04, 1e-3])
    f = LineFeature(0.0, np.zeros(3), z[0], z[1], cov, 10, np.zeros((2, 2)), bTs=ekf.bTs)
    ekf._add_landmark(0, f)
    n = P0.shape[0]
    line_w, G_z, G_pose, G_mount, G_scale = world_line_calibrated(z, ekf.x[POSE], ekf.bTs, 1.0)
    np.testing.assert_allclose(ekf.x[n:], line_w)
    G = np.zeros((2, n))
    G[:, POSE] = G_pose
    G[:, cal.mount] = G_mount
    G[:, cal.scale] = G_scale[:, 0]
    np.testing.assert_allclose(ekf.P[n:, :n], G @ P0, atol=1e-15)
    expected = G @ P0 @ G.T + G_z @ cov @ G_z.T
    np.testing.assert_allclose(ekf.P[n:, n:], expected, rtol=1e-12)
    # the mounting's x and the scale enter a line at 8 m: its rho variance exceeds the pose's
    assert ekf.P[n, n] > (G[:, :3] @ P0[:3, :3] @ G[:, :3].T)[0, 0] + 0.9 * 8.0**2 * 0.04**2


def test_off_by_default_the_state_is_the_vehicle_block():
    ekf = LineEkf(0.0, np.zeros(3), np.eye(3), Mounting(), EkfConfig())
    cal = ekf.calibration_index()
    assert cal.mount is None and cal.scale is None and cal.size == N_VEHICLE
    assert ekf.x.size == N_VEHICLE
    assert not any(k.startswith("state_sonar") for k in ekf.metrics())


@pytest.mark.parametrize("bad", [{"sonar_mount_sigma_m": 0.0}, {"range_scale_sigma": -0.1}])
def test_bad_calibration_priors_are_refused_by_name(bad):
    with pytest.raises(ValueError, match=next(iter(bad))):
        EkfConfig(**bad)
