"""Line associations re-tested when a loop closes (``isam2.retest_window_s``): a recent line
factor whose vote the estimate moved beyond is tested again at the new estimate and removed when
it no longer fits; one that still fits, or whose vote did not move, stays."""

from __future__ import annotations

import gtsam
import numpy as np
from gtsam.symbol_shorthand import L, X

from sonarslam.features.line import LineFeature
from sonarslam.slam.backends.isam2.graph_io import FactorKind, FactorRecord
from sonarslam.slam.backends.isam2.retest import LineRetest

BTS = np.zeros(3)
COV = np.diag([0.05**2, np.deg2rad(0.5) ** 2])


def _feature(t: float, z: tuple[float, float]) -> LineFeature:
    return LineFeature(t, np.zeros(3), z[0], z[1], COV, 10, np.zeros((2, 2)), 10, BTS)


def _graph() -> tuple[gtsam.ISAM2, list[FactorRecord]]:
    """Node X(0) at the origin, known; the wall x = 10 (``rho 10, theta 0``) as L(0), known;
    two observations of it from X(0): one right (rho 10), one 3 m off (a wrong wall)."""
    isam = gtsam.ISAM2()
    g = gtsam.NonlinearFactorGraph()
    g.add(gtsam.PriorFactorPose2(X(0), gtsam.Pose2(), gtsam.noiseModel.Isotropic.Sigma(3, 1e-3)))
    prior = FactorRecord.of(FactorKind.PRIOR_VECTOR, [L(0)], [10.0, 0.0], np.eye(2) * 1e-6)
    g.add(prior.to_gtsam())
    records = [
        FactorRecord.of(FactorKind.LINE_OBSERVATION, [X(0), L(0)], z, COV, bTs=BTS)
        for z in ((10.0, 0.0), (13.0, 0.0))
    ]
    for r in records:
        g.add(r.to_gtsam())
    v = gtsam.Values()
    v.insert(X(0), gtsam.Pose2())
    v.insert(L(0), np.array([10.0, 0.0]))
    isam.update(g, v)
    return isam, records


def test_a_moved_vote_is_retested_and_a_misfit_removed() -> None:
    isam, records = _graph()
    retest = LineRetest(window_s=60.0, gate_probability=0.99)
    cov = np.diag([0.1, 0.1, 1e-4])
    # both associated at a pose 2 m off the estimate now: the estimate moved beyond it
    for r, z in zip(records, ((10.0, 0.0), (13.0, 0.0)), strict=True):
        retest.added(r, 0, 0, _feature(100.0, z), np.zeros(3), np.array([2.0, 0.0, 0.0]), cov)
    retest.indexed(records, [2, 3])
    removed = retest.run(isam, 110.0)
    assert [item.record for item in removed] == [records[1]]
    assert retest.stats == {"retest_runs": 1, "retest_factors": 2, "retest_removed": 1}
    assert list(retest.revised.values()) == [None]


def test_an_unmoved_or_old_vote_is_not_retested() -> None:
    isam, records = _graph()
    retest = LineRetest(window_s=60.0, gate_probability=0.99)
    cov = np.diag([0.1, 0.1, 1e-4])
    # the wrong one associated where the estimate still is; the right one long ago
    retest.added(records[1], 0, 0, _feature(100.0, (13.0, 0.0)), np.zeros(3), np.zeros(3), cov)
    retest.added(records[0], 0, 0, _feature(10.0, (10.0, 0.0)), np.zeros(3), np.ones(3), cov)
    retest.indexed(records[::-1], [3, 2])
    assert retest.run(isam, 110.0) == []
    assert retest.stats["retest_runs"] == 0
