"""slam.eval.consistency: evo's APE/RPE and the NEES/ANEES checked on trajectories with known answers."""

from __future__ import annotations

import numpy as np
import pytest

from sonarslam.datasets.records import GpsSeries
from sonarslam.slam.eval.ate import ate_against_gps, ate_errors
from sonarslam.slam.eval.consistency import (
    NeesSeries,
    anees,
    chi2_band,
    gps_position_nees,
    mean_nees_band,
    nees,
    nees_on_grid,
    nees_series,
    nis,
    window_median_gate,
    window_medians,
)
from sonarslam.slam.eval.evo_metrics import evo_ape, evo_rpe
from sonarslam.slam.io.trajectory import (
    Trajectory,
    cov_file,
    load_run_trajectory,
    write_trajectory_covariances,
    write_tum,
)

T0_S = 1.7e9


def loop_path(n: int = 200, dt_s: float = 0.5) -> Trajectory:
    """A smooth closed loop (an ellipse, 40 m x 20 m) at ``dt_s`` steps, yaw along the path."""
    t = T0_S + dt_s * np.arange(n)
    a = np.linspace(0.0, 2.0 * np.pi, n)
    x, y = 20.0 * np.cos(a), 10.0 * np.sin(a)
    yaw = np.arctan2(10.0 * np.cos(a), -20.0 * np.sin(a))
    return Trajectory(t, np.column_stack([x, y, yaw]))


# -- evo APE / RPE --------------------------------------------------------------------------------


def test_constant_offset_gives_that_ape_and_alignment_removes_it():
    truth = loop_path()
    est = Trajectory(truth.t_s, truth.poses_wTb + np.array([3.0, 4.0, 0.0]))
    ape = evo_ape(truth, est)
    assert ape.n == truth.t_s.size
    for v in (ape.rmse_m, ape.mean_m, ape.median_m, ape.min_m, ape.max_m):
        assert v == pytest.approx(5.0, abs=1e-9)
    assert ape.sd_m == pytest.approx(0.0, abs=1e-9)
    assert evo_ape(truth, est, align=True).rmse_m == pytest.approx(0.0, abs=1e-6)


def test_rotation_about_the_start_is_removed_by_alignment_only():
    truth = loop_path()
    c, s = np.cos(0.1), np.sin(0.1)
    xy = truth.poses_wTb[:, :2] @ np.array([[c, s], [-s, c]]) + np.array([1.0, -2.0])
    est = Trajectory(truth.t_s, np.column_stack([xy, truth.poses_wTb[:, 2] + 0.1]))
    # unaligned: the largest error is at the point farthest from the rotation centre, known
    expected = np.hypot(*(xy - truth.poses_wTb[:, :2]).T)
    ape = evo_ape(truth, est)
    assert ape.max_m == pytest.approx(expected.max(), abs=1e-9)
    assert ape.mean_m == pytest.approx(expected.mean(), abs=1e-9)
    assert evo_ape(truth, est, align=True).max_m == pytest.approx(0.0, abs=1e-6)


def test_evo_ape_equals_the_gps_ate_protocol():
    """Estimate at a jittered 10 Hz, GPS at 1 Hz with noise: evo's interpolating association
    gives the errors of slam.eval.ate (the estimate interpolated at every fix), to 1e-9 m."""
    rng = np.random.default_rng(7)
    truth = loop_path(n=400, dt_s=0.5)
    t_est = T0_S + 0.1 * np.arange(1996) + rng.uniform(-0.03, 0.03, 1996)
    t_est[0], t_est[-1] = T0_S, T0_S + 199.5
    est = Trajectory(t_est, truth.poses(t_est) + rng.normal(0.0, 0.3, (t_est.size, 3)) * [1, 1, 0])
    t_gps = T0_S + np.arange(0.0, 199.6, 1.0)
    en = truth.poses(t_gps)[:, :2] + rng.normal(0.0, 0.5, (t_gps.size, 2))
    gps = GpsSeries(t_gps, en, (42.0, 3.0))
    ate = ate_against_gps(est, gps)
    ref = Trajectory(t_gps, np.column_stack([en, np.zeros(t_gps.size)]))
    ape = evo_ape(ref, est)
    assert ape.n == ate.ate_n == t_gps.size
    assert ape.mean_m == pytest.approx(ate.ate_mean_m, abs=1e-9)
    assert ape.rmse_m == pytest.approx(ate.ate_rmse_m, abs=1e-9)
    assert ape.max_m == pytest.approx(ate.ate_max_m, abs=1e-9)


def test_rpe_per_distance_of_a_10_percent_scale_error():
    """Straight line at 1 m per pose, estimate shrunk by 0.9: over 10 m of reference path the
    relative error is 1.0 m; over the estimate's path (evo's default: the first pose at least
    10 m of path on) pairs are 12 poses (10.8 m) apart, so 1.2 m."""
    n = 101
    t = T0_S + np.arange(n, dtype=float)
    truth = Trajectory(t, np.column_stack([np.arange(n, dtype=float), np.zeros(n), np.zeros(n)]))
    est = Trajectory(t, truth.poses_wTb * [0.9, 1.0, 1.0])
    rpe_ref = evo_rpe(truth, est, delta_m=10.0, pairs_from_reference=True)
    assert rpe_ref.n == 10
    assert rpe_ref.min_m == pytest.approx(1.0, abs=1e-9)
    assert rpe_ref.max_m == pytest.approx(1.0, abs=1e-9)
    rpe_est = evo_rpe(truth, est, delta_m=10.0)
    assert rpe_est.n == 8
    assert rpe_est.mean_m == pytest.approx(1.2, abs=1e-9)
    assert rpe_est.sd_m == pytest.approx(0.0, abs=1e-9)


def test_unknown_sync_is_refused():
    truth = loop_path(n=10)
    with pytest.raises(ValueError, match="sync must be one of"):
        evo_ape(truth, truth, sync="linear")


# -- covariances on disk --------------------------------------------------------------------------


def test_covariances_round_trip_beside_the_tum(tmp_path):
    rng = np.random.default_rng(1)
    tr = loop_path(n=50)
    A = rng.normal(size=(50, 3, 3))
    covs = A @ A.transpose(0, 2, 1) + 0.1 * np.eye(3)
    tr = Trajectory(tr.t_s, tr.poses_wTb, covs)
    write_tum(tmp_path / "ekf.tum", tr)
    assert load_run_trajectory(tmp_path, "ekf").covs is None  # absent: handled
    assert write_trajectory_covariances(tmp_path / cov_file("ekf"), tr) == tmp_path / "ekf_cov.npz"
    back = load_run_trajectory(tmp_path, "ekf")
    np.testing.assert_array_equal(back.covs, covs)
    np.testing.assert_allclose(back.poses_wTb, tr.poses_wTb, atol=1e-12)
    no_cov = Trajectory(tr.t_s, tr.poses_wTb)
    assert write_trajectory_covariances(tmp_path / "none.npz", no_cov) is None
    assert not (tmp_path / "none.npz").exists()


def test_covariances_of_other_times_are_refused(tmp_path):
    tr = loop_path(n=20)
    write_tum(tmp_path / "ekf.tum", tr)
    other = Trajectory(tr.t_s + 0.25, tr.poses_wTb, np.broadcast_to(np.eye(3), (20, 3, 3)).copy())
    write_trajectory_covariances(tmp_path / cov_file("ekf"), other)
    with pytest.raises(ValueError, match="do not match"):
        load_run_trajectory(tmp_path, "ekf")


# -- NEES, NIS, ANEES -----------------------------------------------------------------------------


def test_nees_of_known_errors_with_the_angle_wrapped():
    assert nees([[1.0, 2.0, 0.1]], [np.diag([1.0, 4.0, 0.01])])[0] == pytest.approx(3.0, abs=1e-12)
    t = T0_S + np.arange(3.0)
    truth = Trajectory(t, np.array([[0.0, 0.0, -np.pi + 0.05]] * 3))
    est = Trajectory(
        t, np.array([[0.0, 0.0, np.pi - 0.05]] * 3), np.broadcast_to(np.eye(3) * 0.01, (3, 3, 3))
    )
    s = nees_series(est, truth)
    assert s.dof == 3
    np.testing.assert_allclose(s.nees, 1.0, atol=1e-9)  # error -0.1 rad, not 2 pi - 0.1
    assert nees_series(est, truth, "position").nees == pytest.approx([0.0] * 3, abs=1e-12)
    assert nees_series(est, truth, "heading").dof == 1
    with pytest.raises(ValueError, match="covariances"):
        nees_series(truth, truth)


def test_nis_of_known_innovations():
    s = nis([0.0, 1.0], [[0.3, 0.0], [0.0, 0.02]], [np.diag([0.09, 1.0]), np.diag([1.0, 1e-4])])
    np.testing.assert_allclose(s.nees, [1.0, 4.0], atol=1e-12)
    assert s.dof == 2


def test_gps_position_nees_adds_the_gps_sigma_and_keeps_the_fixes_inside():
    t = T0_S + np.arange(3.0)
    covs = np.stack([np.diag([1.0, 4.0, 0.01]), np.diag([0.25, 0.25, 0.01]), np.eye(3)])
    est = Trajectory(t, np.array([[3.0, 4.0, 0.0]] * 3), covs)
    # fixes at 0 (the first sample's covariance), 1.5 (the second's: last at or before), and
    # two outside the estimate's span
    gps_t = T0_S + np.array([-1.0, 0.0, 1.5, 9.0])
    s = gps_position_nees(est, gps_t, np.zeros((4, 2)), gps_sigma_m=1.0)
    assert s.dof == 2 and s.t_s.tolist() == [T0_S, T0_S + 1.5]
    # (3, 4) off with diag(1 + 1, 4 + 1): 9/2 + 16/5; with diag(1.25, 1.25): 25/1.25
    np.testing.assert_allclose(s.nees, [9.0 / 2.0 + 16.0 / 5.0, 25.0 / 1.25], rtol=1e-12)
    with pytest.raises(ValueError, match="covariances"):
        gps_position_nees(Trajectory(t, est.poses_wTb), gps_t, np.zeros((4, 2)), 1.0)


def test_window_medians_and_their_gate():
    t = T0_S + np.arange(0.0, 250.0, 1.0)
    v = np.where(t - T0_S < 120.0, 1.0, 5.0)
    v[130] = 1e6  # one outlier does not move a median
    edges, med = window_medians(NeesSeries(t, v, 3), 120.0)
    np.testing.assert_allclose(edges - T0_S, [0.0, 120.0, 240.0, 360.0])
    np.testing.assert_allclose(med, [1.0, 5.0, 5.0])
    # chi2.ppf(1 - 0.01 / (2 * 3), 3) and chi2.ppf(1 - 0.01 / 2, 2)
    assert window_median_gate(3, 3, 0.01) == pytest.approx(15.1831, abs=1e-4)
    assert window_median_gate(2, 1, 0.01) == pytest.approx(10.5966, abs=1e-4)
    with pytest.raises(ValueError):
        window_median_gate(3, 0, 0.01)


def test_chi2_bands_match_the_tables():
    assert chi2_band(3) == pytest.approx((0.2158, 9.3484), abs=1e-4)
    assert chi2_band(2) == pytest.approx((0.0506, 7.3778), abs=1e-4)
    # chi2(150) 2.5 % and 97.5 % points 117.985 and 185.800, over 50 runs
    assert mean_nees_band(50, 3) == pytest.approx((2.35969, 3.71601), abs=1e-4)
    with pytest.raises(ValueError):
        mean_nees_band(0, 3)


def test_nees_on_grid_takes_the_last_value_at_or_before():
    from sonarslam.slam.eval.consistency import NeesSeries

    s = NeesSeries(T0_S + np.array([0.0, 1.0, 2.0, 3.0]), np.array([1.0, 2.0, 3.0, 4.0]), 3)
    got = nees_on_grid(s, T0_S, [0.0, 0.5, 1.5, 3.0, 4.0, 10.0])
    np.testing.assert_array_equal(got[:5], [1.0, 1.0, 2.0, 4.0, 4.0])
    assert np.isnan(got[5])  # more than one grid step past the last sample
    assert np.isnan(nees_on_grid(s, T0_S - 5.0, [0.0, 1.0])).all()


def monte_carlo(scale: float, n_runs: int = 50, n_times: int = 100, seed: int = 3):
    """N runs of a trajectory whose errors are drawn from per-time covariances P_k; the runs
    report ``scale * P_k``. Returns the NEES array (N, K) through nees_series and nees_on_grid."""
    rng = np.random.default_rng(seed)
    truth = loop_path(n=n_times, dt_s=1.0)
    A = rng.normal(size=(n_times, 3, 3)) * np.array([0.5, 0.5, 0.02])[:, None]
    P = A @ A.transpose(0, 2, 1) + np.diag([0.01, 0.01, 1e-5])
    L = np.linalg.cholesky(P)
    grid = np.arange(n_times, dtype=float)
    rows = []
    for _ in range(n_runs):
        e = np.einsum("kij,kj->ki", L, rng.standard_normal((n_times, 3)))
        est = Trajectory(truth.t_s, truth.poses_wTb + e, scale * P)
        rows.append(nees_on_grid(nees_series(est, truth), truth.t_s[0], grid))
    return np.array(rows), grid


def test_anees_of_errors_drawn_from_the_covariance_is_inside_the_band():
    X, grid = monte_carlo(1.0)
    res = anees(X, 3, grid)
    assert (res.n_runs == 50).all()
    assert res.band_lo[0] == pytest.approx(2.35969, abs=1e-4)
    assert res.band_hi[0] == pytest.approx(3.71601, abs=1e-4)
    assert res.in_band_fraction >= 0.9  # 0.95 expected, binomial sd 0.022 over 100 times
    lo, hi = mean_nees_band(X.size, 3)  # the mean of all N K independent NEES
    assert lo <= res.mean <= hi
    s = res.summary()
    assert s["anees_runs"] == 50 and s["anees_band_lo"] == pytest.approx(2.35969, abs=1e-4)


@pytest.mark.parametrize(("scale", "side"), [(4.0, "below"), (0.25, "above")])
def test_anees_of_a_scaled_covariance_is_outside_the_band(scale, side):
    X, grid = monte_carlo(scale)
    res = anees(X, 3, grid)
    assert res.in_band_fraction <= 0.02
    assert res.mean == pytest.approx(3.0 / scale, rel=0.1)
    if side == "below":
        assert res.mean < res.band_lo[0]
    else:
        assert res.mean > res.band_hi[0]


def test_anees_counts_the_runs_present_at_each_time():
    X = np.array([[1.0, 2.0, np.nan], [3.0, np.nan, np.nan]])
    res = anees(X, 2)
    np.testing.assert_array_equal(res.n_runs, [2, 1, 0])
    np.testing.assert_allclose(res.anees[:2], [2.0, 2.0], atol=1e-12)
    assert np.isnan(res.anees[2])
    assert res.band_lo[1] == pytest.approx(chi2_band(2)[0], abs=1e-12)
    assert res.band_lo[0] == pytest.approx(mean_nees_band(2, 2)[0], abs=1e-12)


def test_association_scores_on_known_pairings():
    from types import SimpleNamespace

    from sonarslam.features.geometry import compose, line_world_to_frame
    from sonarslam.slam.eval.truth import association_scores
    from sonarslam.slam.io.trajectory import Trajectory

    walls = np.array([[[-10.0, 5.0], [10.0, 5.0]], [[8.0, -10.0], [8.0, 10.0]]])  # y = 5, x = 8
    truth = Trajectory(np.array([0.0, 100.0]), np.array([[0.0, 0.0, 0.3], [1.0, 0.0, 0.3]]))
    bTs = np.array([0.3, 0.0, np.pi])
    lines_w = [np.array([5.0, np.pi / 2]), np.array([8.0, 0.0])]
    feats, lms = [], []
    for k in range(20):
        t = 5.0 * k
        wall = k % 2
        z = line_world_to_frame(lines_w[wall], compose(truth.poses([t])[0], bTs))[0]
        feats.append(SimpleNamespace(t=t, z=z))
        lms.append(wall + 10)  # landmark 10 is wall 0, landmark 11 wall 1
    lms[4] = 11  # one wrong pairing (wall 0 observation to wall 1's landmark)
    lms[6] = None  # one missed
    feats.append(SimpleNamespace(t=50.0, z=np.array([30.0, 1.0])))  # spurious, unpaired
    lms.append(None)
    s = association_scores(feats, lms, walls, truth, bTs)
    assert s.n_associated == 19 and s.n_spurious == 1 and s.n_true_pairs == 20
    assert s.precision == pytest.approx(18 / 19)
    assert s.recall == pytest.approx(18 / 20)


def test_association_scores_collinear_walls_are_one_line_and_seeds_are_not_misses():
    """Two quays on one line are one truth line; the tentative observation that seeded a
    landmark is not counted as a missed association (it is reported as a seed)."""
    from types import SimpleNamespace

    from sonarslam.features.geometry import compose, line_world_to_frame
    from sonarslam.slam.eval.truth import association_scores, wall_lines
    from sonarslam.slam.io.trajectory import Trajectory

    # y = 5 split in two collinear segments, and x = 8
    walls = np.array(
        [[[-10.0, 5.0], [0.0, 5.0]], [[2.0, 5.0], [10.0, 5.0]], [[8.0, -10.0], [8.0, 10.0]]]
    )
    lines, line_of_wall = wall_lines(walls)
    assert lines.shape == (2, 2)
    np.testing.assert_array_equal(line_of_wall, [0, 0, 1])
    truth = Trajectory(np.array([0.0, 100.0]), np.array([[0.0, 0.0, 0.3], [1.0, 0.0, 0.3]]))
    bTs = np.array([0.3, 0.0, np.pi])
    lines_w = [np.array([5.0, np.pi / 2]), np.array([8.0, 0.0])]
    feats, lms, seeds = [], [], []
    for k in range(20):
        t = 5.0 * k
        wall = k % 2
        z = line_world_to_frame(lines_w[wall], compose(truth.poses([t])[0], bTs))[0]
        feats.append(SimpleNamespace(t=t, z=z))
        lms.append(wall + 10)
        seeds.append(None)
    lms[0], seeds[0] = None, 10  # seeded landmark 10 (its own line)
    lms[1], seeds[1] = None, 10  # a wrong seed: a wall-1 observation in landmark 10's tentative
    lms[7] = None  # one missed re-observation of wall 1
    s = association_scores(feats, lms, walls, truth, bTs, feature_seeds=seeds)
    assert s.n_associated == 17 and s.n_seeds == 2 and s.n_spurious == 0
    assert s.precision == pytest.approx(1.0)
    assert s.n_true_pairs == 18 and s.recall == pytest.approx(17 / 18)
    assert s.seed_precision == pytest.approx(0.5)


def test_ate_over_a_span_and_against_the_truth_aligned_or_not():
    """The sonar-span ATE is the ATE of the fixes inside the span only; against the truth, a
    rigidly moved copy of the truth has the move's error, and none once aligned."""
    from sonarslam.slam.eval.ate import ate_against_truth

    t = np.arange(0.0, 100.0, 1.0)
    truth = Trajectory(t, np.column_stack([np.cos(0.05 * t) * 20, np.sin(0.05 * t) * 10, 0 * t]))
    err = np.where(t < 50.0, 1.0, 3.0)  # 1 m off in the first half, 3 m in the second
    est = Trajectory(t, truth.poses_wTb + np.column_stack([err, 0 * t, 0 * t]))
    gps = GpsSeries(t, truth.poses_wTb[:, :2].copy(), (0.0, 0.0))
    assert ate_against_gps(est, gps).ate_mean_m == pytest.approx(2.0, abs=1e-12)
    first = ate_against_gps(est, gps, span_s=(0.0, 49.0))
    assert (first.ate_mean_m, first.ate_n) == (pytest.approx(1.0, abs=1e-12), 50)
    assert first.as_dict("ate_sonar")["ate_sonar_mean_m"] == first.ate_mean_m
    with pytest.raises(ValueError, match="no reference"):
        ate_against_gps(est, gps, span_s=(200.0, 300.0))
    c, s = np.cos(0.1), np.sin(0.1)
    xy = truth.poses_wTb[:, :2] @ np.array([[c, s], [-s, c]]) + [5.0, -2.0]
    moved = Trajectory(t, np.column_stack([xy, truth.poses_wTb[:, 2] + 0.1]))
    assert ate_against_truth(moved, truth).ate_mean_m > 3.0
    assert ate_against_truth(moved, truth, align=True).ate_max_m == pytest.approx(0.0, abs=1e-9)


def test_aligned_ate_against_gps_removes_a_rigid_move_only():
    """Against GPS, as ``evo_ape -a``: a rigidly moved copy of the GPS track has the move's
    error unaligned and none once aligned; a shape error stays after the fit."""
    t = np.arange(0.0, 200.0, 1.0)
    xy = np.column_stack([np.cos(0.03 * t) * 30, np.sin(0.05 * t) * 15])
    gps = GpsSeries(t, xy.copy(), (0.0, 0.0))
    c, s = np.cos(0.05), np.sin(0.05)
    moved = xy @ np.array([[c, s], [-s, c]]) + [3.0, -1.0]
    est = Trajectory(t, np.column_stack([moved, 0 * t]))
    assert ate_against_gps(est, gps).ate_mean_m > 2.0
    assert ate_against_gps(est, gps, align=True).ate_max_m == pytest.approx(0.0, abs=1e-9)
    bent = Trajectory(t, np.column_stack([xy[:, 0], xy[:, 1] + np.where(t < 100, 0.0, 2.0), 0 * t]))
    aligned = ate_against_gps(bent, gps, align=True)
    assert 0.5 < aligned.ate_mean_m < ate_against_gps(bent, gps).ate_mean_m


def test_the_true_trajectory_projects_the_sharpest_map(opened):
    """GPS-free sharpness: a simulated harbour's beams projected with the truth give a lower
    entropy than with its second half turned by 2 deg about the midpoint, or with a drift that
    grows to 3 m; a rigid move of the whole trajectory leaves it (it holds no shape error); the
    whole-run figure is in a dead-reckoning run's metrics.json."""
    from sonarslam.slam.eval.sharpness import trajectory_sharpness
    from sonarslam.slam.eval.truth import truth_trajectory
    from sonarslam.slam.run.presets import map_min_intensity
    from sonarslam.slam.run.run import run_backend

    ds = opened("harbour", 2, 300.0)
    truth = truth_trajectory(ds)
    span = ds.sonar_span_s
    assert span is not None
    p = truth.poses_wTb.copy()
    level = map_min_intensity(ds.beams)

    def turned(from_index: int, angle_rad: float) -> Trajectory:
        q = p.copy()
        c, s = np.cos(angle_rad), np.sin(angle_rad)
        pivot = p[from_index, :2]
        q[from_index:, :2] = (p[from_index:, :2] - pivot) @ np.array([[c, s], [-s, c]]) + pivot
        q[from_index:, 2] += angle_rad
        return Trajectory(truth.t_s, q)

    frac = (truth.t_s - truth.t_s[0]) / (truth.t_s[-1] - truth.t_s[0])
    drifted = Trajectory(truth.t_s, p + np.column_stack([3.0 * frac, 0 * frac, 0 * frac]))
    sharp = trajectory_sharpness(ds, truth, span, level)
    half = turned(p.shape[0] // 2, np.deg2rad(2.0))
    assert sharp < trajectory_sharpness(ds, half, span, level) - 0.01
    assert sharp < trajectory_sharpness(ds, drifted, span, level) - 0.01
    rigid = trajectory_sharpness(ds, turned(0, np.deg2rad(2.0)), span, level)
    assert rigid == pytest.approx(sharp, abs=0.01)
    dr = run_backend(ds, "dr").metrics
    assert dr["map_entropy_nats"] > sharp


def test_the_aligned_ate_of_a_vehicle_that_did_not_move_is_the_centroid_fit() -> None:
    """A stationary run gives a rank-0 cross-covariance, which evo's Umeyama refuses: every
    rotation fits equally, so the aligned errors are those of the centroids' translation."""
    t = np.arange(10.0)
    est = Trajectory(t, np.tile([2.0, -1.0, 0.3], (10, 1)))
    rng = np.random.default_rng(3)
    en_m = np.array([5.0, 4.0]) + rng.normal(0.0, 0.2, (10, 2))
    gps = GpsSeries(t, en_m, (42.0, 3.0))
    _, errors = ate_errors(est, gps, align=True)
    np.testing.assert_allclose(errors, np.hypot(*(en_m.mean(axis=0) - en_m).T), atol=1e-12)


def test_association_scores_see_far_walls_with_the_true_range_scale():
    """A sonar that logs ranges 4 % short sees a wall 30 m off 1.2 m nearer: beyond the 1 m gate
    of the truth unless the scores scale the true lines as the sonar did (a drawn world's
    ``errors.sonar_range_scale``)."""
    from types import SimpleNamespace

    from sonarslam.features.geometry import compose, line_world_to_frame
    from sonarslam.slam.eval.truth import association_scores
    from sonarslam.slam.io.trajectory import Trajectory

    walls = np.array([[[-50.0, 30.0], [50.0, 30.0]], [[8.0, -50.0], [8.0, 50.0]]])
    truth = Trajectory(np.array([0.0, 100.0]), np.array([[0.0, 0.0, 0.3], [1.0, 0.0, 0.3]]))
    bTs = np.array([0.3, 0.0, np.pi])
    scale = 0.96
    lines_w = [np.array([30.0, np.pi / 2]), np.array([8.0, 0.0])]
    feats, lms = [], []
    for k in range(10):
        t = 10.0 * k
        z = line_world_to_frame(lines_w[k % 2], compose(truth.poses([t])[0], bTs))[0]
        feats.append(SimpleNamespace(t=t, z=z * np.array([scale, 1.0])))
        lms.append(k % 2)
    unscaled = association_scores(feats, lms, walls, truth, bTs)
    assert unscaled.n_spurious == 5  # every far-wall line misses the gate
    s = association_scores(feats, lms, walls, truth, bTs, range_scale=scale)
    assert s.n_spurious == 0 and s.precision == pytest.approx(1.0)
