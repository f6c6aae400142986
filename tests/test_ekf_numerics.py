"""The EKF's own numerics: the rank-1 Joseph update against filterpy's, and the batched
prediction against step-by-step propagation (seeded random states, explicit tolerances)."""

from __future__ import annotations

import numpy as np
import pytest
from filterpy.kalman import ExtendedKalmanFilter

from sonarslam.datasets.config import NoiseConfig
from sonarslam.slam.backends.ekf import N_VEHICLE, EkfConfig, LineEkf, scalar_joseph_update
from sonarslam.slam.model.motion import MotionStep
from sonarslam.sonar.beam import Mounting


def _random_spd(rng: np.random.Generator, n: int) -> np.ndarray:
    A = rng.normal(size=(n, n))
    P = A @ A.T / n + 0.1 * np.eye(n)
    return 0.5 * (P + P.T)  # exactly symmetric, as the filter keeps it


@pytest.mark.parametrize("seed", range(5))
def test_scalar_joseph_update_equals_filterpys_joseph_form(seed: int) -> None:
    """x and P after one scalar measurement, ours (O(n^2)) and filterpy's full Joseph form."""
    rng = np.random.default_rng(seed)
    n = int(rng.integers(7, 60))
    x, P = rng.normal(size=n), _random_spd(rng, n)
    h = np.zeros(n)
    h[rng.choice(n, size=3, replace=False)] = rng.normal(size=3)
    r = float(rng.uniform(1e-4, 1.0))
    z = float(h @ x + rng.normal())
    kf = ExtendedKalmanFilter(dim_x=n, dim_z=1)
    kf.x, kf.P = x.copy(), P.copy()
    kf.update(np.array([z]), lambda _x: h[None, :], lambda _x: np.array([h @ _x]), R=r)
    x1, P1 = scalar_joseph_update(x, P, h, z - float(h @ x), r)
    scale = float(np.abs(P).max())
    np.testing.assert_allclose(x1, kf.x, rtol=0.0, atol=1e-12 * (1.0 + np.abs(x).max()))
    np.testing.assert_allclose(P1, kf.P, rtol=0.0, atol=1e-12 * scale)
    assert np.array_equal(P1, P1.T)  # symmetric by construction, exactly


def test_scalar_joseph_update_keeps_a_near_singular_covariance_positive() -> None:
    """A measurement far more precise than the prior: the posterior stays PSD and its variance
    along h is the measurement's (to relative 1e-6)."""
    rng = np.random.default_rng(7)
    n = 12
    P = 1e4 * _random_spd(rng, n)
    h = np.zeros(n)
    h[2] = h[3] = 1.0
    r = 1e-6
    _, P1 = scalar_joseph_update(np.zeros(n), P, h, 0.0, r)
    assert np.linalg.eigvalsh(P1).min() > -1e-9 * np.abs(P1).max()
    var_h = float(h @ P1 @ h)
    assert var_h == pytest.approx(r * float(h @ P @ h) / (float(h @ P @ h) + r), rel=1e-3)


def _filter_with_landmarks(rng: np.random.Generator, n_landmarks: int) -> LineEkf:
    cfg = EkfConfig(estimate_misalignment=True, noise=NoiseConfig(dvl_scale_sigma=0.02))
    ekf = LineEkf(0.0, np.array([1.0, -2.0, 0.3]), np.eye(3), Mounting(), cfg)
    n = N_VEHICLE + 2 * n_landmarks
    x = rng.normal(size=n)
    x[N_VEHICLE::2] = np.abs(x[N_VEHICLE::2]) + 1.0  # rho > 0
    ekf.kf.x, ekf.kf.P = x, _random_spd(rng, n)
    return ekf


@pytest.mark.parametrize("seed", range(3))
def test_batched_prediction_equals_step_by_step(seed: int) -> None:
    """Forty steps predicted in one batch (the covariance read once) and one at a time (read
    after each, which applies every step to the whole covariance): the same state and
    covariance to round-off."""
    rng = np.random.default_rng(seed)
    a, b = _filter_with_landmarks(rng, 6), _filter_with_landmarks(np.random.default_rng(seed), 6)
    for k in range(40):
        step = MotionStep(
            t_s=0.1 * (k + 1),
            dt_s=0.1,
            dx_m=float(rng.normal(0.1, 0.05)),
            dy_m=float(rng.normal(0.0, 0.02)),
            dyaw_rad=float(rng.normal(0.0, 0.02)),
            sigma_v_mps=0.02,
            held_s=0.1 * (1 + k % 3),
            gyro_dt_s=0.1 if k % 2 else 0.0,
        )
        a.predict(step)
        b.predict(step)
        _ = b.P  # flushes: step by step
    Pa, Pb = a.P, b.P
    np.testing.assert_allclose(a.x, b.x, rtol=0.0, atol=1e-15 * (1.0 + np.abs(b.x).max()))
    np.testing.assert_allclose(Pa, Pb, rtol=0.0, atol=1e-12 * np.abs(Pb).max())
    np.testing.assert_allclose(Pa, Pa.T, rtol=0.0, atol=1e-12 * np.abs(Pa).max())
    # the landmark block never moves; the vehicle-landmark block did
    V, P0 = N_VEHICLE, _filter_with_landmarks(np.random.default_rng(seed), 6).P
    assert np.array_equal(Pa[V:, V:], P0[V:, V:])
    assert np.abs(Pa[:V, V:] - P0[:V, V:]).max() > 1e-3 * np.abs(P0[:V, V:]).max()


def test_line_updates_keep_the_covariance_exactly_symmetric() -> None:
    """Two hundred line updates (filterpy's Joseph form) on a filter whose variances span ten
    orders of magnitude, as a long survey's do: P stays exactly symmetric and positive
    definite (unsymmetrised, its round-off asymmetry grows until a gate's squared Mahalanobis
    distance can go negative)."""
    from sonarslam.slam.backends.ekf import POSE, _filter
    from sonarslam.slam.model.lines import line_prediction

    rng = np.random.default_rng(11)
    ekf = _filter_with_landmarks(rng, 8)
    n = ekf.x.size
    d = np.full(n, 1e-2)
    d[:2], d[2:4] = 1e2, 1e-8  # a channel's position and a well-known heading
    P0 = _random_spd(rng, n) * np.sqrt(np.outer(d, d))
    ekf.kf = _filter(ekf.x.copy(), 0.5 * (P0 + P0.T) + np.diag(d))
    R = np.diag([0.05**2, np.deg2rad(0.5) ** 2])
    for _ in range(200):
        j = int(rng.integers(8))
        i = N_VEHICLE + 2 * j
        z_hat, H_pose, H_line = line_prediction(ekf.x[POSE], ekf.x[i : i + 2], ekf.bTs)
        H = np.zeros((2, n))
        H[:, POSE], H[:, i : i + 2] = H_pose, H_line
        z = z_hat + rng.multivariate_normal(np.zeros(2), R)
        ekf._update(z, H, z_hat, R, lambda a, b: a - b)
    P = ekf.P
    assert np.array_equal(P, P.T)
    assert np.linalg.eigvalsh(P).min() > 0.0
