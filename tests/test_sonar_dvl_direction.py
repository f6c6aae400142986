"""The sonar's direction of motion against the DVL's (issue 29 item 3): what the registrations of
nearby scans measure, and the mounting prior that puts the sonar's yaw relative to the DVL's
track (``isam2.sonar_yaw_prior = "dead_reckoning"``)."""

from __future__ import annotations

import warnings
from collections.abc import Callable
from pathlib import Path

import gtsam
import numpy as np
import pytest
from gtsam.symbol_shorthand import C, D
from gtsam.utils.numerical_derivative import numericalDerivative21, numericalDerivative22

from sonarslam.datasets.errors import DataWarning
from sonarslam.datasets.source import open_dataset
from sonarslam.slam.backends.isam2.config import GraphConfig
from sonarslam.slam.backends.isam2.factors import mount_prior_dvl_factor, mount_prior_dvl_residual
from sonarslam.slam.backends.isam2.graph_io import FactorKind, FactorRecord, start_records
from sonarslam.slam.eval.loops import odometry_pairs
from sonarslam.slam.run.sources import dead_reckoning_trajectory

#: The registrations of one pair of scans, with and without a turned DVL or sonar yaw, agree to
#: this (deg): the same scans, motion-corrected with a slightly different dead reckoning.
PAIRED_TOL_DEG = 0.15


def test_mount_prior_dvl_jacobians_match_numerical_derivatives() -> None:
    rng = np.random.default_rng(7)
    cov = np.diag([0.04, 0.04, np.deg2rad(0.5) ** 2])
    for _ in range(5):
        z = np.array([0.3, 0.0, np.pi]) + rng.normal(0.0, 0.1, 3)
        f = mount_prior_dvl_factor(C(0), D(0), z, cov)
        mount = z + rng.normal(0.0, 0.2, 3)
        delta = rng.normal(0.0, 0.1, 1)
        v = gtsam.Values()
        v.insert(C(0), mount)
        v.insert(D(0), delta)
        e, H_m, H_d = mount_prior_dvl_residual(z, mount, float(delta[0]))
        yaw_err = (mount[2] - delta[0] - z[2] + np.pi) % (2 * np.pi) - np.pi
        assert np.allclose(e, [mount[0] - z[0], mount[1] - z[1], yaw_err], atol=1e-12)
        assert np.allclose(f.unwhitenedError(v), e, atol=1e-12)
        A, _ = f.linearize(v).jacobian()  # whitened, through GTSAM
        R_sqrt = gtsam.noiseModel.Gaussian.Covariance(cov).R()
        assert np.allclose(A, R_sqrt @ np.hstack([H_m, H_d]), atol=1e-9)

        def err(m: np.ndarray, d: np.ndarray, f: gtsam.CustomFactor = f) -> np.ndarray:
            vv = gtsam.Values()
            vv.insert(C(0), m)
            vv.insert(D(0), d)
            return f.unwhitenedError(vv)

        for fn, analytic in ((numericalDerivative21, H_m), (numericalDerivative22, H_d)):
            assert np.allclose(analytic, fn(err, mount, delta, 1e-6), atol=1e-8)
    rec = FactorRecord.of(FactorKind.MOUNT_PRIOR_DVL, [C(0), D(0)], z, cov)
    back = FactorRecord.from_json(rec.to_json())
    assert back.keys == rec.keys
    assert np.allclose(back.to_gtsam().unwhitenedError(v), rec.to_gtsam().unwhitenedError(v))


@pytest.mark.parametrize("prior", ["body", "dead_reckoning"])
def test_a_yaw_disagreement_goes_where_the_prior_puts_it(prior: str) -> None:
    """The data see the mounting's yaw minus the misalignment; here a measurement of that
    difference 1 deg above the calibration. With the yaw's prior on the yaw itself (``"body"``),
    the loose misalignment takes it (and would turn the track); with the prior on the
    difference (a yaw calibrated with dead-reckoning poses), it is the two priors' 1:0 split of
    a yaw that disagrees with its calibration: the misalignment keeps its prior mean and the
    yaw moves by the data's weight."""
    bTs = np.array([0.3, 0.0, np.pi])
    config = GraphConfig(
        estimate_sonar_mount=True, estimate_misalignment=True, sonar_yaw_prior=prior
    )
    records, values = start_records(np.zeros(3), np.eye(3), config, bTs)
    graph = gtsam.NonlinearFactorGraph()
    for r in records:
        if set(r.keys) <= {int(C(0)), int(D(0))}:
            graph.add(r.to_gtsam())
    kinds = {r.kind for r in records if int(C(0)) in r.keys}
    expected = FactorKind.MOUNT_PRIOR_DVL if prior == "dead_reckoning" else FactorKind.PRIOR_VECTOR
    assert kinds == {expected}
    # the data: yaw - delta measured 1 deg above the calibration, to 0.5 deg
    sigma_data, sigma_yaw = np.deg2rad(0.5), np.deg2rad(config.sonar_mount_sigma_deg)
    data = bTs + np.array([0.0, 0.0, np.deg2rad(1.0)])
    graph.add(mount_prior_dvl_factor(C(0), D(0), data, np.diag([1e6, 1e6, sigma_data**2])))
    start = gtsam.Values()
    start.insert(C(0), values.atVector(C(0)))
    start.insert(D(0), values.atVector(D(0)))
    est = gtsam.LevenbergMarquardtOptimizer(graph, start).optimize()
    yaw = np.rad2deg(est.atVector(C(0))[2] - np.pi)
    delta = np.rad2deg(est.atVector(D(0))[0])
    var_d = np.deg2rad(config.misalignment_sigma_deg) ** 2
    if prior == "body":
        # yaw - delta = 1 deg shared by inverse variance: the misalignment's 25 deg^2 and the
        # yaw's 0.25 against the data's 0.25
        w_yaw, w_d = sigma_yaw**2, var_d
        total = w_yaw + w_d + sigma_data**2
        assert yaw == pytest.approx(1.0 * w_yaw / total, abs=1e-6)
        assert delta == pytest.approx(-1.0 * w_d / total, abs=1e-6)
    else:
        # the misalignment is free along the gauge and stays at its prior mean; the difference
        # is the calibration's and the data's inverse-variance mean
        assert delta == pytest.approx(0.0, abs=1e-6)
        w = sigma_data**2 / (sigma_data**2 + sigma_yaw**2)
        assert yaw == pytest.approx(1.0 * (1.0 - w), abs=1e-6)


@pytest.fixture(scope="module")
def harbour(simulated: Callable[..., Path]) -> Path:
    return simulated("harbour", 2, 300.0)


def _pairs(folder: Path, override: str | None, tmp: Path) -> dict[float, float]:
    cfg = None
    if override is not None:
        cfg = tmp / f"o{abs(hash(override))}.toml"
        cfg.write_text(override)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DataWarning)
        d = open_dataset(folder, config_override=cfg)
    pairs = odometry_pairs(d, dead_reckoning_trajectory(d), step_m=3.0, n_pairs=30)
    return {round(p.t0_s, 3): float(np.rad2deg(p.angle_rad)) for p in pairs if p.sonar is not None}


def test_the_registrations_measure_the_dvl_direction_minus_the_sonar_yaw(
    harbour: Path, tmp_path: Path
) -> None:
    """Turning the DVL's mounting yaw by 1 deg turns dead reckoning's translation by 1 deg and
    the measured angle by -1 deg; turning the sonar's as well leaves the angle as it was (the
    two turn the track and the map together: the direction the data cannot see)."""
    base = _pairs(harbour, None, tmp_path)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DataWarning)
        d = open_dataset(harbour)
    dvl = float(np.rad2deg(d.config.dvl_mounting.yaw_rad)) + 1.0
    sonar = float(np.rad2deg(d.config.sonar_mounting.yaw_rad)) + 1.0
    turned_dvl = _pairs(harbour, f"[mounting.dvl]\nyaw_deg = {dvl}\n", tmp_path)
    both = _pairs(
        harbour, f"[mounting.dvl]\nyaw_deg = {dvl}\n[mounting.sonar]\nyaw_deg = {sonar}\n", tmp_path
    )
    # the simulated harbour has no crab and its sonar the told mounting: the angle is 0
    assert len(base) >= 15
    assert abs(np.mean(list(base.values()))) < 0.3
    for other, shift in ((turned_dvl, -1.0), (both, 0.0)):
        common = sorted(set(base) & set(other))
        assert len(common) >= 0.8 * len(base)
        diff = np.array([other[t] - base[t] for t in common])
        assert np.median(diff) == pytest.approx(shift, abs=PAIRED_TOL_DEG)
