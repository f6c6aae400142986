"""The back ends estimate the DVL's scale-factor error (``dvl_scale_sigma``) from the line
landmarks: on a drift world whose DVL reads ``(1 + k_true) v + b`` they find the scale that
undoes it along the track, ``1 / (1 + k_true + b_forward / speed) - 1`` (a forward bias looks
like a scale error to a vehicle that moves forward at a steady speed)."""

from __future__ import annotations

import json
import math
from collections.abc import Callable
from dataclasses import replace

import numpy as np
import pytest
from gtsam.symbol_shorthand import K

from sonarslam.datasets.config import NoiseConfig
from sonarslam.datasets.dataset import Dataset
from sonarslam.datasets.simulator.scenario import make_scenario
from sonarslam.slam.backends.ekf import N_VEHICLE, EkfConfig, LineEkf
from sonarslam.slam.backends.registry import backend_spec
from sonarslam.slam.model.motion import MotionStep
from sonarslam.slam.run.closed_loop import run_closed_loop
from sonarslam.slam.run.presets import run_config
from sonarslam.sonar.beam import Mounting


@pytest.fixture
def drift(opened: Callable[..., Dataset]) -> Dataset:
    """900 s of the drift world, seed 2 (tests/test_sonar_calibration.py's run: simulated and
    read once per session)."""
    return opened("drift", 2, 900.0)


@pytest.mark.parametrize("name", ["ekf", "isam2"])
def test_the_dvl_scale_error_is_found(drift: Dataset, name: str) -> None:
    ds = drift
    assert ds.config.noise.dvl_scale_sigma == pytest.approx(0.02)  # the world's specification
    truth = json.loads((ds.root / "truth.json").read_text())
    k_true = truth["errors"]["dvl_scale_factor"]
    # the DVL's y axis is the body's forward axis (mounting yaw -90 deg)
    assert truth["mountings"]["dvl"]["yaw_rad"] == pytest.approx(-math.pi / 2)
    b_forward = truth["errors"]["dvl_bias_mps"][1]
    expected = 1.0 / (1.0 + k_true + b_forward / make_scenario("drift", 2).speed_mps) - 1.0
    config = run_config(ds.beams, name, noise=ds.config.noise)
    if name == "isam2":
        # lines measure distances in the sonar's ranges: with the range scale a state too they
        # observe only the ratio of the two scales, so the sonar is the reference here
        config = replace(config, backend=replace(config.backend, range_scale_sigma=0.0))
    spec = backend_spec(name)
    mounting = ds.config.sonar_mounting
    res = run_closed_loop(
        ds,
        lambda t0, p0, P0: spec.make(t0, p0, P0, mounting, config.backend),
        config.extractor,
        progress=False,
    )
    be = res.backend
    if name == "ekf":
        k, sigma = float(be.x[5]), math.sqrt(be.P[5, 5])
    else:
        k = float(be.isam.calculateEstimateVector(K(0))[0])
        sigma = math.sqrt(be.isam.marginalCovariance(K(0))[0, 0])
    assert sigma < 0.5 * 0.02  # the lines told it something
    assert abs(k - expected) < 3.0 * sigma + 1e-3, (k, expected, sigma)
    assert np.sign(k) == np.sign(expected)


def test_the_ekf_prediction_jacobian_matches_numerical_derivatives() -> None:
    """``F`` of :meth:`LineEkf.predict` (pose, misalignment, DVL scale and gyro bias columns)
    is the derivative of the step it takes: P' = F P F^T + Q with P = eps I and Q subtracted."""
    cfg = EkfConfig(estimate_misalignment=True, noise=NoiseConfig(dvl_scale_sigma=0.02))
    step = MotionStep(1.0, 1.0, 0.8, -0.3, 0.05, 0.0, 1.0, gyro_dt_s=1.0)

    def propagate(x0: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        ekf = LineEkf(0.0, x0[:3], np.zeros((3, 3)), Mounting(), cfg)
        ekf.kf.x = x0.copy()
        ekf.kf.P = np.eye(N_VEHICLE)
        ekf.predict(step)
        return ekf.x.copy(), ekf.P.copy()

    x0 = np.array([2.0, -1.0, 0.7, 0.01, 0.05, 0.015, 0.012])
    _, P1 = propagate(x0)
    eps = 1e-6
    F_num = np.empty((N_VEHICLE, N_VEHICLE))
    for j in range(N_VEHICLE):
        d = np.zeros(N_VEHICLE)
        d[j] = eps
        F_num[:, j] = (propagate(x0 + d)[0] - propagate(x0 - d)[0]) / (2 * eps)
    ekf = LineEkf(0.0, x0[:3], np.zeros((3, 3)), Mounting(), cfg)
    ekf.kf.x = x0.copy()
    ekf.kf.P = np.zeros((N_VEHICLE, N_VEHICLE))
    ekf.predict(step)
    Q = ekf.P.copy()
    assert np.allclose(P1 - Q, F_num @ F_num.T, atol=1e-6)
