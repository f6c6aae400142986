"""Line observations re-decided at smoothed poses (slam/mapping/redecide.py) and the graph
re-optimised with them (slam/backends/isam2/redecided.py), against the truth of small
simulated worlds: a curved wall split into stretches, a wrong association moved, an observation
that fits nothing dropped, and the re-optimised poses back on the truth."""

from __future__ import annotations

import gtsam
import numpy as np
import pytest
from gtsam.symbol_shorthand import L, X

from sonarslam.features.geometry import (
    along_line,
    between,
    compose,
    line_difference,
    line_world_to_frame,
    normalize_line,
)
from sonarslam.slam.backends.isam2.graph_io import FactorKind, FactorRecord
from sonarslam.slam.backends.isam2.redecided import line_observations, redecided_graph
from sonarslam.slam.mapping.redecide import (
    LineObservations,
    RedecideConfig,
    fit_line,
    redecide,
    split_along,
)

R_OBS = np.diag([0.1**2, np.deg2rad(1.0) ** 2])  # sigma 0.1 m, 1 deg


def _observe(wTs: np.ndarray, line_w: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    z, _, _ = line_world_to_frame(line_w, wTs)
    return z + rng.multivariate_normal(np.zeros(2), R_OBS)


def _tangent(radius_m: float, centre: np.ndarray, phi: float) -> np.ndarray:
    """The tangent line of a circle at angle ``phi`` (normal pointing away from the centre)."""
    rho = radius_m + centre @ np.array([np.cos(phi), np.sin(phi)])
    r, t = normalize_line(rho, phi)
    return np.array([float(r), float(t)])


def test_a_curved_wall_is_cut_into_stretches_that_each_fit_the_wall_where_it_was_seen():
    # a wall on a circle of radius 600 m around (0, 610): its nearest point to (0, 0) is at
    # y = 10, and it sags 1.7 m over 90 m and turns by 8.6 deg. The sonar sees it from 10 m
    # south every 3 m from x = -45 to 45: at each place the wall's tangent there
    rng = np.random.default_rng(3)
    radius, centre = 600.0, np.array([0.0, 610.0])
    xs = np.arange(-45.0, 45.1, 3.0)
    wTs, z = [], []
    for x in xs:
        pose = np.array([x, 0.0, 0.3])
        tangent = _tangent(radius, centre, float(np.arctan2(-centre[1], x - centre[0])))
        wTs.append(pose)
        z.append(_observe(pose, tangent, rng))
    n = len(xs)
    obs = LineObservations(np.array(wTs), np.array(z), np.tile(R_OBS, (n, 1, 1)), np.arange(n))
    one = np.zeros(n, dtype=int)

    cut = redecide(obs, one, RedecideConfig(max_stretch_m=40.0))
    whole = redecide(obs, one, RedecideConfig(max_stretch_m=1000.0))

    # 90 m in three stretches, each at most 40 m; the stretches follow the curve: every
    # observation but the two at the ends of the first one fits its stretch (their 1 deg noise
    # and the 1.7 deg the wall turns over a stretch), within 0.3 m and 3.1 deg (the gate: 3 sd)
    assert len(cut.stretches.members) == 3
    assert np.all(np.diff(cut.stretches.extents_m, axis=1) <= 40.0 + 1e-9)
    assert cut.dropped <= 2 and cut.moved == 0
    for i in np.flatnonzero(cut.stretch >= 0):
        line = cut.stretches.lines_w[cut.stretch[i]]
        d, _ = line_difference(obs.z[i], line_world_to_frame(line, obs.wTs[i])[0])
        assert abs(d[0]) < 0.3 and abs(np.rad2deg(d[1])) < 3.1
    # one straight line for all of it fits few of them: the rest are dropped
    assert len(whole.stretches.members) == 1
    assert whole.dropped > n // 2


def test_a_wrong_association_is_moved_to_the_wall_it_fits_and_an_outlier_is_dropped():
    # two parallel walls 4 m apart (y = 10 and y = 14: the far one seen past the near one's end)
    # seen from 12 poses along x; observation 5 of the far wall was associated with the near
    # one (a drifting estimate's decision); observation 8 fits neither wall
    rng = np.random.default_rng(7)
    near, far = np.array([10.0, np.pi / 2]), np.array([14.0, np.pi / 2])
    wTs, z, landmark = [], [], []
    for k in range(12):
        pose = np.array([2.0 * k, 0.0, 0.1])
        for lm, line in ((0, near), (1, far)):
            wTs.append(pose)
            z.append(_observe(pose, line, rng))
            landmark.append(lm)
    z_arr, lm_arr = np.array(z), np.array(landmark)
    wrong = 2 * 5 + 1  # the far wall's observation from pose 5, labelled the near wall
    lm_arr[wrong] = 0
    outlier = 2 * 8  # the near wall's observation from pose 8, 3 m off and 10 deg turned
    z_arr[outlier] += np.array([3.0, np.deg2rad(10.0)])
    n = len(z_arr)
    votes = np.repeat(np.arange(12), 2)
    obs = LineObservations(np.array(wTs), z_arr, np.tile(R_OBS, (n, 1, 1)), votes)

    out = redecide(obs, lm_arr, RedecideConfig(max_stretch_m=40.0))

    assert out.stretch[outlier] == -1 and out.dropped == 1
    assert out.moved == 1
    # the wrong one now shares its stretch with the far wall's other observations
    far_stretch = out.stretch[2 * 4 + 1]
    assert out.stretch[wrong] == far_stretch
    assert np.all(out.stretch[1::2] == far_stretch)
    # and the stretches' lines are the walls within 0.1 m and 0.5 deg
    lines = out.stretches.lines_w
    for truth, j in ((near, out.stretch[0]), (far, far_stretch)):
        d, _ = line_difference(lines[j], truth)
        assert abs(d[0]) < 0.1 and abs(np.rad2deg(d[1])) < 0.5


def test_split_along_cuts_equal_pieces_of_at_most_the_stretch():
    s = np.array([0.0, 10.0, 39.0, 41.0, 79.0, 100.0])
    labels = split_along(s, 40.0)  # 100 m: 3 pieces of 33.3 m
    assert labels.tolist() == [0, 0, 1, 1, 2, 2]
    assert split_along(np.array([5.0, 5.0]), 40.0).tolist() == [0, 0]
    assert split_along(np.zeros(0), 40.0).size == 0


def test_fit_line_finds_the_wall_from_a_poor_start_with_its_covariance():
    rng = np.random.default_rng(11)
    truth = np.array([12.0, np.deg2rad(80.0)])
    poses = np.array([[x, 0.0, 0.2 * x / 10] for x in np.linspace(-20.0, 20.0, 9)])
    z = np.array([_observe(p, truth, rng) for p in poses])
    obs = LineObservations(poses, z, np.tile(R_OBS, (9, 1, 1)), np.arange(9))
    line, cov = fit_line(obs, np.arange(9), truth + np.array([2.0, 0.1]), iterations=10)
    d, _ = line_difference(line, truth)
    sd = np.sqrt(np.diag(cov))
    assert abs(d[0]) < 3 * sd[0] and abs(d[1]) < 3 * sd[1]
    assert sd[0] < 0.1 and sd[1] < np.deg2rad(1.0)


def test_observations_of_mismatched_shapes_are_refused():
    with pytest.raises(ValueError, match="LineObservations.R"):
        LineObservations(np.zeros((2, 3)), np.zeros((2, 2)), np.zeros((3, 2, 2)), np.arange(2))
    obs = LineObservations(np.zeros((1, 3)), np.ones((1, 2)), R_OBS[None], np.arange(1))
    with pytest.raises(ValueError, match="landmark"):
        redecide(obs, np.zeros(2, dtype=int), RedecideConfig())


def _graph(
    rng: np.random.Generator, wrong: bool
) -> tuple[list[FactorRecord], gtsam.Values, np.ndarray]:
    """A vehicle driving 80 m east along a wall (y = 12) and back 6 m further south past a pier
    face (y = 2, seen from the south on the way back only), exact odometry with sigma 0.05 m /
    0.2 deg per step, a prior on the start; with ``wrong``, half the way back's observations of
    the wall are labelled as the pier (the decision of a drifting estimate). The values start
    at the poses dead reckoning with a 0.3 deg/step heading error gives."""
    truth = [np.array([4.0 * k, 0.0, 0.0]) for k in range(21)]
    truth += [np.array([80.0 - 4.0 * k, -6.0, np.pi]) for k in range(1, 21)]
    wall, pier = np.array([12.0, np.pi / 2]), np.array([-2.0, np.pi / 2])  # y = 12 and y = 2
    bTs = np.array([0.5, 0.0, 0.0])
    odo_cov = np.diag([0.05**2, 0.05**2, np.deg2rad(0.2) ** 2])
    records = [
        FactorRecord.of(FactorKind.PRIOR_POSE, [X(0)], truth[0], np.diag([1e-4, 1e-4, 1e-6]))
    ]
    for k in range(1, len(truth)):
        rel = between(truth[k - 1], truth[k])
        records.append(FactorRecord.of(FactorKind.BETWEEN_POSE, [X(k - 1), X(k)], rel, odo_cov))
    robust = None  # no kernel: the wrong decisions bend the graph in full
    for k, pose in enumerate(truth):
        wTs = compose(pose, bTs)
        seen = [(0, wall)] if k <= 20 else [(0, wall), (1, pier)]
        for lm, line in seen:
            if k > 20 and k % 2 == 0 and lm == 0 and wrong:
                lm = 1
            records.append(
                FactorRecord.of(
                    FactorKind.LINE_OBSERVATION,
                    [X(k), L(lm)],
                    _observe(wTs, line, rng),
                    R_OBS,
                    bTs=bTs,
                    robust=robust,
                )
            )
    values = gtsam.Values()
    drifted = truth[0]
    values.insert(X(0), gtsam.Pose2(*drifted))
    for k in range(1, len(truth)):
        rel = between(truth[k - 1], truth[k]) + np.array([0.0, 0.0, np.deg2rad(0.3)])
        drifted = compose(drifted, rel)
        values.insert(X(k), gtsam.Pose2(*drifted))
    values.insert(L(0), wall + np.array([0.5, 0.0]))
    values.insert(L(1), pier + np.array([0.5, 0.0]))
    return records, values, np.array(truth)


def _error(values: gtsam.Values, truth: np.ndarray) -> float:
    est = np.array(
        [[values.atPose2(X(k)).x(), values.atPose2(X(k)).y()] for k in range(len(truth))]
    )
    return float(np.hypot(*(est - truth[:, :2]).T).max())


def _optimum(records: list[FactorRecord], values: gtsam.Values) -> gtsam.Values:
    graph = gtsam.NonlinearFactorGraph()
    for r in records:
        graph.add(r.to_gtsam())
    return gtsam.LevenbergMarquardtOptimizer(graph, values).optimize()


def test_the_graph_re_optimised_with_its_lines_re_decided_is_back_on_the_truth():
    records, values, truth = _graph(np.random.default_rng(5), wrong=True)
    right, _, _ = _graph(np.random.default_rng(5), wrong=False)  # the same draws, well decided
    as_decided = _optimum(records, values)
    well_decided = _optimum(right, values)

    out = redecided_graph(records, as_decided, RedecideConfig(max_stretch_m=40.0), passes=2)

    m = out.metrics()
    assert m["redecided_observations"] == 61 and m["redecided_passes"] == 2
    assert m["redecided_moved"] == 10  # every wrong one back on the wall
    assert m["redecided_dropped"] <= 1
    # the sonar's feet on the wall span 80.5 m: three stretches; on the pier 76 m: two
    assert m["redecided_stretches"] == 5
    # the wrong decisions bend the way back; re-decided, the poses are as far from the truth as
    # the graph with the right associations (whose error is the lines' noise) within 3 cm
    best = _error(well_decided, truth)
    assert _error(as_decided, truth) > best + 0.5
    assert _error(out.values, truth) < best + 0.03
    # every factor that is not a line's is kept as it was
    kept = [r for r in out.records if r.kind is not FactorKind.LINE_OBSERVATION]
    assert kept == [r for r in records if r.kind is not FactorKind.LINE_OBSERVATION]


def test_line_observations_group_a_vote_and_join_landmarks_tied_by_an_equality():
    rng = np.random.default_rng(2)
    records, values, _ = _graph(rng, wrong=False)
    records.append(
        FactorRecord.of(FactorKind.LINE_EQUALITY, [L(0), L(1)], [0.0], np.diag([1e-6, 1e-10]))
    )
    rows, obs, landmark = line_observations(records, values)
    assert len(rows) == len(obs) == 61
    assert np.all(landmark == landmark[0])  # tied: one landmark
    assert len(np.unique(obs.vote)) == 41  # one vote per node (one bTs each)
    wTs0 = compose(np.array([values.atPose2(X(0)).x(), 0.0, 0.0]), np.array([0.5, 0.0, 0.0]))
    assert np.allclose(obs.wTs[0], wTs0)
    assert along_line(np.array([12.0, np.pi / 2]), obs.wTs[:1, :2])[0] == pytest.approx(-0.5)


def test_an_observation_the_loop_left_unassociated_joins_the_wall_it_fits():
    rng = np.random.default_rng(13)
    wall = np.array([10.0, np.pi / 2])
    poses = np.array([[3.0 * k, 0.0, 0.0] for k in range(8)])
    z = np.array([_observe(p, wall, rng) for p in poses])
    obs = LineObservations(poses, z, np.tile(R_OBS, (8, 1, 1)), np.arange(8))
    landmark = np.zeros(8, dtype=int)
    landmark[3] = -1
    out = redecide(obs, landmark, RedecideConfig())
    assert out.dropped == 0 and out.moved == 1
    assert np.all(out.stretch == 0)
    alone = redecide(obs, -np.ones(8, dtype=int), RedecideConfig())  # no landmark to join
    assert alone.dropped == 8 and alone.moved == 0
