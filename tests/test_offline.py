"""The offline estimate (slam/backends/isam2/offline.py) and its parts: the joint decision by
graduated non-convexity (gnc.py) and the noise scales from the residuals (variance.py)."""

from __future__ import annotations

import json

import gtsam
import numpy as np
import pytest
from gtsam.symbol_shorthand import X

from sonarslam.features.geometry import between, compose
from sonarslam.slam.backends.isam2.gnc import gnc_tls
from sonarslam.slam.backends.isam2.graph_io import FactorKind, FactorRecord, pose_of
from sonarslam.slam.backends.isam2.offline import (
    GROUPS,
    OFFLINE_REVISIT,
    _partition_changes,
    _variance_components,
    group_of,
)
from sonarslam.slam.backends.isam2.variance import variance_component


def _chain(rng: np.random.Generator, n: int, odo_sigma: np.ndarray, true_scale: float):
    """A pose chain in a square loop with odometry whose noise is ``sqrt(true_scale)`` times
    the sigma it states, loop closures to the start every 10 poses (stated and true sigma
    0.05 m, 0.5 deg): records and the true poses."""
    truth = [np.zeros(3)]
    for k in range(1, n):
        step = np.array([1.0, 0.0, np.pi / 2 if k % 10 == 0 else 0.0])
        truth.append(compose(truth[-1], step))
    records = [
        FactorRecord.of(FactorKind.PRIOR_POSE, [X(0)], np.zeros(3), np.diag([1e-6, 1e-6, 1e-8]))
    ]
    cov = np.diag(odo_sigma**2)
    for k in range(1, n):
        z = between(truth[k - 1], truth[k]) + rng.normal(0.0, np.sqrt(true_scale) * odo_sigma)
        records.append(FactorRecord.of(FactorKind.BETWEEN_POSE, [X(k - 1), X(k)], z, cov))
    loop_sigma = np.array([0.05, 0.05, np.deg2rad(0.5)])
    for k in range(10, n, 10):
        z = between(truth[0], truth[k]) + rng.normal(0.0, loop_sigma)
        records.append(
            FactorRecord.of(
                FactorKind.BETWEEN_POSE,
                [X(0), X(k)],
                z,
                np.diag(loop_sigma**2),
                constraint=OFFLINE_REVISIT,
            )
        )
    return records, np.array(truth)


def _optimise(records: list[FactorRecord], start: np.ndarray) -> gtsam.Values:
    graph = gtsam.NonlinearFactorGraph()
    for r in records:
        graph.add(r.to_gtsam())
    values = gtsam.Values()
    for k, p in enumerate(start):
        values.insert(X(k), gtsam.Pose2(*p))
    return gtsam.LevenbergMarquardtOptimizer(graph, values).optimize()


@pytest.mark.parametrize("true_scale", [1.0, 4.0, 9.0])
def test_variance_components_recover_the_scale_of_understated_odometry(true_scale):
    """Odometry whose errors are ``sqrt(s)`` times its stated sigma: iterated, the odometry
    group's scale is ``s`` within 25 % (400 factors) and the loop closures' (stated right) 1
    within 40 %. One step alone is biased low (the redundancy is shared out with the wrong
    weights): the scales are re-estimated at each re-optimised estimate."""
    rng = np.random.default_rng(7)
    odo_sigma = np.array([0.02, 0.02, np.deg2rad(0.2)])
    records, truth = _chain(rng, 400, odo_sigma, true_scale)
    values = _optimise(records, truth)
    params = gtsam.LevenbergMarquardtParams()
    scales, _ = _variance_components(
        records, dict.fromkeys(GROUPS, 1.0), ("odometry", "revisit"), values, params, 30, 1e-3
    )
    assert scales["odometry"] == pytest.approx(true_scale, rel=0.25)
    assert scales["revisit"] == pytest.approx(1.0, rel=0.4)
    assert scales["line"] == scales["heading"] == 1.0  # not estimated


def test_variance_component_of_a_group():
    """One step on the right model: the scale is about 1, the counts are the group's."""
    rng = np.random.default_rng(5)
    records, truth = _chain(rng, 300, np.array([0.02, 0.02, np.deg2rad(0.2)]), 1.0)
    values = _optimise(records, truth)
    graph = gtsam.NonlinearFactorGraph()
    for r in records:
        graph.add(r.to_gtsam())
    odometry = [r for r in records if group_of(r) == "odometry"]
    vc = variance_component(odometry, values, gtsam.Marginals(graph, values))
    assert vc.n == len(odometry)
    assert 0.0 < vc.redundancy < 3 * len(odometry)
    assert vc.scale == pytest.approx(1.0, rel=0.3)


def test_variance_component_redundancy_is_the_trace_identity():
    """The redundancies of every factor of a graph add up to its measurements' dimension
    minus its variables' (sum r_i = m - n for a full-rank least-squares problem)."""
    rng = np.random.default_rng(3)
    records, truth = _chain(rng, 60, np.array([0.02, 0.02, 0.003]), 1.0)
    values = _optimise(records, truth)
    graph = gtsam.NonlinearFactorGraph()
    for r in records:
        graph.add(r.to_gtsam())
    marginals = gtsam.Marginals(graph, values)
    vc = variance_component(records, values, marginals)
    m = sum(r.z.size for r in records)
    assert vc.redundancy == pytest.approx(m - 3 * len(truth), abs=1e-3)


def test_gnc_rejects_planted_false_loop_closures_and_keeps_the_true_ones():
    """Nine true loop closures and three false ones (4-9 m off), from a start 0.3 m off: the
    joint decision keeps the true nine and drops the three, and its optimum is the graph's
    with the true ones alone (within 1 mm)."""
    rng = np.random.default_rng(11)
    records, truth = _chain(rng, 100, np.array([0.02, 0.02, 0.003]), 1.0)
    loops = [r for r in records if r.constraint == OFFLINE_REVISIT]
    known = gtsam.NonlinearFactorGraph()
    for r in records:
        if r.constraint != OFFLINE_REVISIT:
            known.add(r.to_gtsam())
    false = []
    for k, off in ((25, 4.0), (55, -6.0), (85, 8.0)):
        z = between(truth[3], truth[k]) + np.array([off, off / 2, 0.0])
        false.append(
            FactorRecord.of(
                FactorKind.BETWEEN_POSE, [X(3), X(k)], z, np.diag([0.05**2, 0.05**2, 1e-4])
            )
        )
    start = gtsam.Values()
    for k, p in enumerate(truth):
        start.insert(X(k), gtsam.Pose2(*(p + rng.normal(0.0, [0.3, 0.3, 0.01]))))
    params = gtsam.LevenbergMarquardtParams()
    found = gnc_tls(known, [*loops, *false], start, c2=11.34, params=params)
    assert set(found.inliers.tolist()) == set(range(len(loops)))
    assert np.all(found.weights[len(loops) :] < 1e-6)
    clean = _optimise([r for r in records], truth)
    est = np.array([pose_of(found.values.atPose2(X(k))) for k in range(len(truth))])
    ref = np.array([pose_of(clean.atPose2(X(k))) for k in range(len(truth))])
    assert np.max(np.hypot(*(est[:, :2] - ref[:, :2]).T)) < 1e-3


def test_groups_of_the_offline_graph():
    """Each factor kind falls in the group whose scale the data may set; priors in none."""
    odo = FactorRecord.of(FactorKind.BETWEEN_POSE, [X(0), X(1)], np.zeros(3), np.eye(3))
    rev = FactorRecord.of(
        FactorKind.BETWEEN_POSE, [X(0), X(1)], np.zeros(3), np.eye(3), constraint=OFFLINE_REVISIT
    )
    scan = FactorRecord.of(
        FactorKind.BETWEEN_POSE, [X(0), X(1)], np.zeros(3), np.eye(3), constraint="scan-revisit"
    )
    prior = FactorRecord.of(FactorKind.PRIOR_POSE, [X(0)], np.zeros(3), np.eye(3))
    assert [group_of(r) for r in (odo, rev, scan, prior)] == ["odometry", "revisit", "", ""]
    assert set(GROUPS) == {"odometry", "heading", "revisit", "line"}


def test_partition_changes_are_counted_up_to_labels():
    """Relabelled stretches are no change; a split, a merge, a drop are, per observation."""
    a = np.array([0, 0, 1, 1, 2, -1])
    assert _partition_changes(a, np.array([5, 5, 3, 3, 7, -1])) == 0
    assert _partition_changes(a, np.array([0, 0, 1, 4, 2, -1])) == 2  # stretch 1 split
    assert _partition_changes(a, np.array([0, 0, 0, 0, 2, -1])) == 4  # 0 and 1 merged
    assert _partition_changes(a, np.array([0, 0, 1, 1, -1, -1])) == 1  # one dropped
    assert _partition_changes(None, a) == a.size
    assert json.dumps({"n": _partition_changes(a, a)}) == '{"n": 0}'


def test_the_offline_estimate_of_a_run_beats_dead_reckoning_and_is_its_saved_runs(
    simulated, tmp_path
):
    """900 s of the drift world (seed 2), the default iSAM2 run (two passes): the offline estimate is
    written (``isam2_offline.tum`` and its covariances, ``offline_*`` in metrics.json); it
    beats dead reckoning against the truth by 20 % (measured: 3.18 m against 4.57) and its
    shape (rigidly aligned) is within 0.5 m; every covariance is symmetric positive definite;
    and the API on the saved run (``offline_from_saved``: graph.json and the dataset) gives
    the same estimate to the micrometre."""
    from sonarslam import offline_from_saved, open_dataset
    from sonarslam.slam.io.trajectory import read_trajectory_covariances, read_tum
    from sonarslam.slam.run.run import run

    source = simulated("drift", 2, 900.0)
    two = {"isam2.offline.max_passes": "2"}  # the saved run's own settings: the API takes them
    done = run(source, "isam2", tmp_path / "isam2", progress=False, settings=two)
    dr = run(source, "dr", tmp_path / "dr", progress=False).metrics["ate_truth_mean_m"]
    m = done.metrics
    assert m["ate_truth_offline_mean_m"] < 0.8 * dr, (m["ate_truth_offline_mean_m"], dr)
    assert m["ate_truth_aligned_offline_mean_m"] < 0.5
    assert m["offline_revisits_kept"] >= 8 and m["offline_scans"] > 50
    assert 1 <= m["offline_passes"] <= 2 and m["offline_lines_stretches"] >= 1
    assert min(m[f"offline_{g}_scale"] for g in GROUPS) >= 1.0
    t_s, covs = read_trajectory_covariances(tmp_path / "isam2" / "isam2_offline_cov.npz")
    assert covs.shape == (t_s.size, 3, 3)
    assert np.allclose(covs, np.transpose(covs, (0, 2, 1)), atol=1e-12)
    assert np.all(np.linalg.eigvalsh(covs) > 0.0)
    again = offline_from_saved(tmp_path / "isam2", open_dataset(source))
    written = read_tum(tmp_path / "isam2" / "isam2_offline.tum")
    poses = written.poses(again.trajectory.t_s)
    assert np.max(np.abs(poses[:, :2] - again.trajectory.poses_wTb[:, :2])) < 1e-6


def test_the_offline_estimate_is_off_with_one_setting(simulated, tmp_path):
    """``--set isam2.offline=false`` (the alias of ``isam2.offline.enabled``): no offline
    trajectory, file or figure; its fields are set by ``isam2.offline.FIELD``."""
    from sonarslam.slam.run.offline import wants_offline
    from sonarslam.slam.run.presets import backend_config
    from sonarslam.slam.run.run import run

    assert wants_offline(backend_config("isam2", {}))
    assert not wants_offline(backend_config("isam2", {"offline": "false"}))
    assert backend_config("isam2", {"offline.max_passes": "2"}).offline.max_passes == 2
    assert not wants_offline(backend_config("ekf", {}))
    off = run(
        simulated("harbour", 4, 100.0),
        "isam2",
        tmp_path / "off",
        progress=False,
        settings={"isam2.offline": "false"},
    )
    assert "offline" not in off.trajectories and "offline_passes" not in off.metrics
    assert not (tmp_path / "off" / "isam2_offline.tum").exists()


def test_offline_from_saved_refuses_another_runs_dataset(simulated, tmp_path):
    """A saved run given another dataset is refused: another world on the same clock by its
    files' digest (the run's provenance), a part of the run's own by the spans too (its nodes
    outside that part's navigation); a folder that is no run is refused by name."""
    from sonarslam import offline_from_saved, open_dataset
    from sonarslam.settings import SettingError
    from sonarslam.slam.run.run import run

    run(simulated("harbour", 4, 100.0), "isam2", tmp_path / "r", progress=False)
    other = open_dataset(simulated("harbour", 5, 100.0))
    part = open_dataset(simulated("harbour", 4, 100.0), span_s=(60.0, 90.0))
    with pytest.raises(SettingError, match="is not the dataset .* was run on"):
        offline_from_saved(tmp_path / "r", other)
    with pytest.raises(SettingError, match="is not the run's dataset"):
        offline_from_saved(tmp_path / "r", part, check_dataset=False)
    with pytest.raises(SettingError, match="no such run directory"):
        offline_from_saved(tmp_path / "nothing", other)
    # the run's own data opened with another sonar mounting (a review: rebuilt silently with it)
    used = (tmp_path / "r" / "config_used.toml").read_text()
    assert "[mounting.sonar]" in used
    turned = tmp_path / "turned.toml"
    turned.write_text("[mounting.sonar]\nx_m = 0.0\ny_m = 0.0\nyaw_deg = 20.0\n")
    source = simulated("harbour", 4, 100.0)
    with pytest.raises(SettingError, match=r"another configuration .*\[mounting.sonar\] yaw_deg"):
        offline_from_saved(tmp_path / "r", open_dataset(source, config_override=turned))
    own = open_dataset(source, config_override=tmp_path / "r" / "config_used.toml")
    from sonarslam.slam.run.offline import _check_config

    _check_config(tmp_path / "r", own)  # the run's own configuration passes
