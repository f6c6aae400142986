"""The noise learned online: the relative pose error of the walks against Monte Carlo, the gate's
expectation, the learner recovering a walk and a measurement scale on a filter of its own, the
heading walk learned only where the gyro turns the heading, ``noise.csv``."""

from __future__ import annotations

import math

import numpy as np
import pytest
from gtsam.symbol_shorthand import B
from scipy.stats import chi2

from sonarslam.datasets.errors import DataError
from sonarslam.slam.backends.ekf import AHRS_BIAS
from sonarslam.slam.backends.registry import backend_spec
from sonarslam.slam.io.plots import plot_learned_noise
from sonarslam.slam.io.states import NOISE_FILE, read_learned_noise, write_learned_noise
from sonarslam.slam.model.motion import MotionStep
from sonarslam.slam.model.noise_learning import (
    NoiseLearner,
    PathMoments,
    expected_factor,
    walk_sensitivities,
)
from sonarslam.sonar.beam import Mounting


def _path(n: int = 400, dt: float = 0.5) -> tuple[np.ndarray, np.ndarray]:
    """A curving path at 1 m/s: times (n,), positions (n, 2)."""
    t = dt * np.arange(n)
    yaw = 0.3 * np.sin(t / 40.0) + t / 120.0
    v = np.column_stack([np.cos(yaw), np.sin(yaw)])
    p = np.vstack([np.zeros(2), np.cumsum(v[:-1] * dt, axis=0)])
    return t, p


def test_path_moments_integrate_the_path() -> None:
    t, p = _path()
    m = PathMoments()
    for ti, pi in zip(t, p, strict=True):
        m.advance(float(ti), pi)
    T, m1, m2, p_now = m.snapshot()
    rel = p - p[0]
    assert T == pytest.approx(t[-1] - t[0], abs=1e-12)
    # trapezoids of a piecewise-linear path: exact to its linear pieces
    np.testing.assert_allclose(m1, np.trapezoid(rel, t, axis=0), rtol=1e-12, atol=1e-9)
    outer = np.einsum("ni,nj->nij", rel, rel)
    np.testing.assert_allclose(m2, np.trapezoid(outer, t, axis=0), rtol=2e-3, atol=1e-6)
    np.testing.assert_allclose(p_now, rel[-1], atol=1e-12)  # the position now, relative


def test_walk_sensitivities_match_monte_carlo() -> None:
    """The pose error at the end of a path, relative to its start, of a heading error walking at
    ``q`` and of a DVL scale error walking at ``q``: its covariance per unit ``q`` is
    :func:`walk_sensitivities`' (the module's derivation by parts), within the Monte Carlo's
    sampling error."""
    rng = np.random.default_rng(3)
    t, p = _path(n=241)
    dt = np.diff(t)
    v = np.diff(p, axis=0) / dt[:, None]
    m = PathMoments()
    m.advance(float(t[0]), p[0])
    start = m.snapshot()
    for ti, pi in zip(t[1:], p[1:], strict=True):
        m.advance(float(ti), pi)
    D_h, D_k = walk_sensitivities(start, m.snapshot(), m.relative(p[-1]))
    n = 6000
    # heading error walking from 0 over each step (its value at the step's start moves it)
    e = np.cumsum(rng.normal(0.0, np.sqrt(dt), (n, dt.size)), axis=1)
    e_start = np.hstack([np.zeros((n, 1)), e[:, :-1]])
    perp = np.column_stack([-v[:, 1], v[:, 0]])
    dp = np.einsum("ns,sk->nk", e_start * dt, perp)
    err_h = np.column_stack([dp, e[:, -1]])
    cov_h = np.cov(err_h.T)
    sd = np.sqrt(np.diag(D_h))
    np.testing.assert_allclose(cov_h / np.outer(sd, sd), D_h / np.outer(sd, sd), atol=0.06)
    # a DVL scale error walking: each step's displacement times (1 + k)
    k = np.cumsum(rng.normal(0.0, np.sqrt(dt), (n, dt.size)), axis=1)
    k_start = np.hstack([np.zeros((n, 1)), k[:, :-1]])
    err_k = np.einsum("ns,sk->nk", k_start * dt, v)
    cov_k = np.cov(err_k.T)
    sd = np.sqrt(np.diag(D_k[:2, :2]))
    np.testing.assert_allclose(cov_k / np.outer(sd, sd), D_k[:2, :2] / np.outer(sd, sd), atol=0.06)
    assert np.all(D_k[2] == 0.0)


@pytest.mark.parametrize(("dof", "gate"), [(2, 0.99), (4, 0.99), (3, None)])
def test_expected_factor(dof: int, gate: float | None) -> None:
    """``E[nu nu^T] = c S`` of a chi2(d) innovation kept inside its gate, or winsorised."""
    rng = np.random.default_rng(5)
    x = rng.normal(size=(400_000, dof))
    r2 = np.sum(x**2, axis=1)
    c, w = expected_factor(dof, gate)
    if gate is not None:
        assert w == pytest.approx(chi2.ppf(gate, dof))
        kept = r2[r2 <= w]
        assert float(np.mean(kept)) / dof == pytest.approx(c, rel=3e-3)
    else:
        assert float(np.mean(np.minimum(r2, w))) / dof == pytest.approx(c, rel=3e-3)


def test_learner_recovers_a_walk_and_a_measurement_scale() -> None:
    """A scalar state walking at ``q`` seen after gaps of 1 to 200 s with a noise 4 times the
    told one; a Kalman filter told no walk and the noise as told learns both (its derivatives
    of the innovation variance by each propagated exactly), within 40 % over the last 2,000
    innovations."""
    rng = np.random.default_rng(1)
    q_true, r0, lam_true = 1e-5, 3e-4, 4.0
    learner = NoiseLearner({"heading_walk": 0.0, "line_scale": 1.0}, memory_s=40_000.0, every=5)
    x = xh = 0.0
    P, dPq, dPl, t = 1e-3, 0.0, 0.0, 0.0
    q_seen, lam_seen = [], []
    for k in range(6000):
        dt = float(rng.choice([1.0, 5.0, 50.0, 200.0]))
        t += dt
        x += rng.normal(0.0, math.sqrt(q_true * dt))
        q, lam = learner.value("heading_walk"), learner.value("line_scale")
        P += q * dt
        dPq += dt
        nu = x + rng.normal(0.0, math.sqrt(lam_true * r0)) - xh
        S = P + lam * r0
        D = {"heading_walk": np.array([[dPq]]), "line_scale": np.array([[dPl + r0]])}
        learner.add(t, np.array([nu]), np.array([[S]]), D)
        K = P / S
        xh += K * nu
        P *= 1.0 - K
        dPq *= (1.0 - K) ** 2
        dPl = (1.0 - K) ** 2 * dPl + K**2 * r0
        if k >= 4000:
            q_seen.append(learner.value("heading_walk"))
            lam_seen.append(learner.value("line_scale"))
    assert np.mean(q_seen) == pytest.approx(q_true, rel=0.4)
    assert np.mean(lam_seen) == pytest.approx(lam_true, rel=0.4)
    assert learner.history[0][1][0] == 0.0  # the start: the floors
    assert min(v[1][2] for v in learner.history) >= 1.0  # never below the told noise


def test_learner_stays_at_its_floor_when_told_right() -> None:
    """Innovations drawn as the told noise predicts them: the learned values stay near their
    floors (the mean over the last 2,000 innovations within 10 % of the line scale's, the walk
    within a tenth of its reference size)."""
    rng = np.random.default_rng(2)
    q0 = 1e-6
    learner = NoiseLearner({"line_scale": 1.0, "heading_walk": q0}, memory_s=500.0, every=5)
    R = np.diag([0.04, 1e-4])
    h = np.array([[5.0], [-1.0]])  # a line's derivative by the heading
    lam_seen, q_seen = [], []
    for k in range(4000):
        D_h = float(rng.uniform(1.0, 100.0)) * h @ h.T
        truth = R + q0 * D_h + 1e-3 * np.eye(2)
        nu = rng.multivariate_normal(np.zeros(2), truth)
        lam, q = learner.value("line_scale"), learner.value("heading_walk")
        S = lam * R + q * D_h + 1e-3 * np.eye(2)
        learner.add(float(k), nu, S, {"line_scale": R, "heading_walk": D_h})
        if k >= 2000:
            lam_seen.append(learner.value("line_scale"))
            q_seen.append(learner.value("heading_walk"))
    assert np.mean(lam_seen) < 1.10
    assert np.mean(q_seen) < q0 + 0.1 * math.radians(0.1) ** 2


@pytest.mark.parametrize("name", ["ekf", "isam2"])
def test_the_heading_walk_is_learned_where_the_gyro_turns_the_heading(name: str) -> None:
    """A loop whose first step turns by the gyro keeps learning the heading walk (from its
    start value: the bias's variance grows by it, and the graph gets a bias per node); one
    whose first step turns by the AHRS heading's own change learns it no more (the told walk,
    here none: one bias)."""
    spec = backend_spec(name)
    cfg = spec.config_type(learn_noise="heading,lines", learn_heading_start_deg_per_sqrt_s=0.2)
    q = math.radians(0.2) ** 2
    for gyro in (True, False):
        be = spec.make(0.0, np.zeros(3), np.eye(3) * 0.01, Mounting(), cfg)
        for k in range(1, 101):
            dt = 0.1
            be.predict(MotionStep(k * dt, dt, 0.1, 0.0, 0.0, 0.05, 0.1, gyro_dt_s=dt * gyro))
        assert be.noise.learns("heading_walk") is gyro
        assert be.noise.learns("line_scale")
        if name == "ekf":
            told = math.radians(cfg.noise.ahrs_bias_sigma_deg) ** 2
            assert be.P[AHRS_BIAS, AHRS_BIAS] == pytest.approx(told + gyro * q * 10.0, rel=1e-9)
        else:
            be.finish()
            keys = {int(k) for k in be.isam.getLinearizationPoint().keys()}
            assert (int(B(1)) in keys) is gyro


def test_noise_csv_round_trip_and_figure(tmp_path) -> None:
    """``noise.csv`` reads back what was written (NaN where not learned), refuses another
    header naming the file and line, and ``sonarslam report`` draws it."""
    t = np.array([100.0, 110.0, 130.0])
    v = np.array(
        [[0.0, np.nan, 1.0, np.nan], [0.05, np.nan, 1.5, np.nan], [0.1, np.nan, 2.0, np.nan]]
    )
    path = write_learned_noise(tmp_path / NOISE_FILE, t, v)
    t2, v2 = read_learned_noise(path)
    np.testing.assert_allclose(t2, t, atol=1e-6)
    np.testing.assert_allclose(v2, v, rtol=1e-5, equal_nan=True)
    bad = tmp_path / "bad.csv"
    bad.write_text("t,b\n1,2\n")
    with pytest.raises(DataError, match="bad.csv"):
        read_learned_noise(bad)
    png = plot_learned_noise(tmp_path / "noise.png", t2, v2, "learned")
    assert png.stat().st_size > 1000
