"""The EKF's sonar calibration states (``ekf.estimate_sonar_mount``, ``ekf.range_scale_sigma``):
the shared calibrated line model's Jacobians (:func:`line_prediction_calibrated`,
:func:`world_line_calibrated`) and the filter's assembled line Jacobian against central
differences; a new landmark's covariance as the first-order image of the state's; and on a
seeded drawn world with a mounting offset and a range-scale error, the final estimates within
2 sigma of the simulator's truth."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from sonarslam.datasets.errors import DataWarning
from sonarslam.datasets.source import open_dataset
from sonarslam.features.geometry import line_difference, normalize_line
from sonarslam.features.line import LineFeature
from sonarslam.slam.backends.ekf import N_VEHICLE, POSE, EkfConfig, LineEkf, _filter
from sonarslam.slam.eval.truth import CALIBRATION_SD_KEYS, calibration_sigmas, true_calibration
from sonarslam.slam.model.calibration import line_prediction_calibrated, world_line_calibrated
from sonarslam.slam.model.lines import line_prediction
from sonarslam.slam.run.run import run_backend
from sonarslam.slam.run.sonar_calibration import write_sonar_calibration
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


@pytest.mark.parametrize(
    "bad",
    [
        {"sonar_mount_sigma_m": 0.0},
        {"range_scale_sigma": -0.1},
        # a prior on yaw minus misalignment with either not estimated changed nothing, silently
        {"sonar_yaw_prior": "dead_reckoning"},
        {"sonar_yaw_prior": "dead_reckoning", "estimate_sonar_mount": True},
    ],
)
def test_bad_calibration_priors_are_refused_by_name(bad):
    with pytest.raises(ValueError, match=next(iter(bad))):
        EkfConfig(**bad)


#: The drawn world of the end-to-end check: a tuning seed (docs/research/calibration.md), 600 s.
DRAWN_SEED, DRAWN_DURATION_S = 1, 600.0


def test_on_a_drawn_world_the_ekf_finds_the_mounting_and_range_scale(simulated, tmp_path):
    """A drawn world's sonar is mounted off the told mounting and logs its ranges scaled (the
    simulator's ``truth.json``); with the four states on, each final estimate lies within 2 of
    its own sigma of the truth, each sigma is below half its prior's (the lines observed it),
    and the range scale and the lever arm end nearer the truth than half the prior mean's
    error."""
    folder = simulated("drawn", DRAWN_SEED, DRAWN_DURATION_S)
    calibration = write_sonar_calibration(folder, tmp_path / "calibration.toml")  # GPS-free
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DataWarning)
        ds = open_dataset(folder, config_override=calibration)
        settings = {"ekf.estimate_sonar_mount": True, "ekf.range_scale_sigma": 0.04}
        res = run_backend(ds, "ekf", settings)
    assert res.closed_loop is not None
    m = res.closed_loop.backend.metrics()
    truth = true_calibration(ds, res.trajectory.span_s[1])
    told = ds.config.sonar_mounting.as_pose()
    assert abs(truth["state_sonar_range_scale"] - 1.0) > 0.02  # an error to find
    assert np.hypot(*(told[:2] - [truth["state_sonar_x_m"], truth["state_sonar_y_m"]])) > 0.05
    prior_sd = {
        "state_sonar_x_m": 0.2,
        "state_sonar_y_m": 0.2,
        "state_sonar_yaw_deg": 0.5,
        "state_sonar_range_scale": 0.04,
    }
    for key, sd0 in prior_sd.items():
        z = calibration_sigmas(m, truth, key)
        assert abs(z) <= 2.0, (key, m[key], truth[key], z)
        assert m[CALIBRATION_SD_KEYS[key]] < 0.5 * sd0, key
    # and moved from the prior mean towards the truth: the range scale, the lever arm
    s_true = truth["state_sonar_range_scale"]
    assert abs(m["state_sonar_range_scale"] - s_true) < 0.5 * abs(1.0 - s_true)
    xy_true = np.array([truth["state_sonar_x_m"], truth["state_sonar_y_m"]])
    xy = np.array([m["state_sonar_x_m"], m["state_sonar_y_m"]])
    assert np.hypot(*(xy - xy_true)) < 0.5 * np.hypot(*(told[:2] - xy_true))
    # the run's metrics.json carries them (the factor graph's keys)
    assert res.metrics["state_sonar_range_scale"] == pytest.approx(m["state_sonar_range_scale"])
