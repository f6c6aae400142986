"""The AHRS bias as a random walk (``ahrs_bias_walk_deg_per_sqrt_s``): both back ends grow its
variance by ``walk**2 dt`` and agree on what the AHRS headings tell them."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import pytest
from gtsam.symbol_shorthand import B

from sonarslam.datasets.config import NoiseConfig
from sonarslam.datasets.dataset import Dataset
from sonarslam.slam.backends.registry import backend_spec
from sonarslam.slam.eval.truth import truth_trajectory
from sonarslam.slam.model.motion import MotionStep
from sonarslam.slam.run.run import run_backend
from sonarslam.sonar.beam import Mounting

WALK_DEG = 0.2  # deg / sqrt(s)


def _run(name: str, walk_deg: float, headings: bool, seconds: int = 120):
    spec = backend_spec(name)
    extra = {"node_period_s": 5.0} if name == "isam2" else {}
    config = spec.config_type(noise=NoiseConfig(ahrs_bias_walk_deg_per_sqrt_s=walk_deg), **extra)
    P0 = np.diag([0.1, 0.1, np.deg2rad(1.0) ** 2])
    be = spec.make(0.0, np.zeros(3), P0, Mounting(), config)
    rng = np.random.default_rng(4)
    for k in range(1, 10 * seconds + 1):
        t = 0.1 * k
        be.predict(MotionStep(t, 0.1, 0.1, 0.0, 0.0, 0.02, 0.1))
        if headings:
            be.update_heading(t, float(rng.normal(0.0, np.deg2rad(1.0))))
    be.finish()
    return be, config


def _bias_var(name: str, be) -> float:
    if name == "ekf":
        return float(be.P[3, 3])
    be._update()
    return float(be.isam.marginalCovariance(B(be.n_nodes - 1))[0, 0])


@pytest.mark.parametrize("name", ["ekf", "isam2"])
def test_without_headings_the_bias_variance_grows_by_the_walk(name: str):
    be, config = _run(name, WALK_DEG, headings=False)
    t = be.t_s if name == "ekf" else be.nodes.t_s[-1]
    expected = np.deg2rad(config.noise.ahrs_bias_sigma_deg) ** 2 + np.deg2rad(WALK_DEG) ** 2 * t
    assert _bias_var(name, be) == pytest.approx(expected, rel=1e-6)


def test_a_constant_bias_keeps_one_bias_variable():
    be, _ = _run("isam2", 0.0, headings=False, seconds=30)
    be._update()
    keys = {int(k) for k in be.isam.getLinearizationPoint().keys()}
    assert int(B(0)) in keys and int(B(1)) not in keys


def test_the_back_ends_agree_on_the_current_heading_under_a_walk():
    """With AHRS headings the filter's and the smoother's marginal of the newest heading (a linear
    problem here) agree; the walk makes it wider than with a constant bias."""
    ekf, _ = _run("ekf", WALK_DEG, headings=True)
    graph, _ = _run("isam2", WALK_DEG, headings=True)
    graph._update()
    var_ekf = ekf.pose_cov[2, 2]
    var_graph = graph.pose_cov[2, 2]
    assert var_graph == pytest.approx(var_ekf, rel=0.1)
    ekf_const, _ = _run("ekf", 0.0, headings=True)
    assert ekf_const.pose_cov[2, 2] < 0.9 * var_ekf


@pytest.fixture(scope="module")
def drift_300s(opened: Callable[..., Dataset]) -> Dataset:
    """300 s of the drift world: its AHRS heading walks (0.15 deg/sqrt(s)), the estimators are
    told the walk's rate (simulated and read once per session)."""
    return opened("drift", 2, 300.0)


@pytest.mark.parametrize("name", ["ekf", "isam2"])
def test_no_back_end_learns_the_unobservable_rotation(drift_300s: Dataset, name: str) -> None:
    """A rotation of the whole map and trajectory with the opposite change of the AHRS bias
    changes no measurement: the heading's variance never falls below the bias prior's, and its
    error against the truth stays consistent with it (FEJ-EKF: Huang et al. 2008)."""
    ds = drift_300s
    run = run_backend(ds, name, {})
    tr = run.trajectory
    assert tr.covs is not None
    var_yaw = tr.covs[:, 2, 2]
    sigma_b = np.deg2rad(run.closed_loop.backend.config.noise.ahrs_bias_sigma_deg)
    assert var_yaw.min() >= 0.99 * sigma_b**2
    err = np.angle(np.exp(1j * (tr.poses_wTb[:, 2] - truth_trajectory(ds).poses(tr.t_s)[:, 2])))
    assert np.mean(err**2 / var_yaw) < 2.5  # one run of a correlated series: a loose bound
