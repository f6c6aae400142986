"""The pose sources' batch covariances (one call per vote of the extractor) against their own
time-by-time :meth:`covariance`: the same values, exactly."""

from __future__ import annotations

import numpy as np

from sonarslam.features.pose_source import BatchCovariances, PoseSource, pose_covariances
from sonarslam.slam.backends.base import AnchoredOdometry
from sonarslam.slam.backends.isam2.pose_source import NodeTable, SmoothedPoseSource
from sonarslam.slam.io.trajectory import Trajectory
from sonarslam.slam.model.motion import OdometryChain


def _odometry(rng: np.random.Generator) -> tuple[AnchoredOdometry, np.ndarray]:
    odo = AnchoredOdometry(0.0, np.array([1.0, 2.0, 0.3]))
    t = np.cumsum(rng.uniform(0.0, 0.2, 300))  # some steps share a time (dt = 0 is rare)
    t[50] = t[49]
    for tk in t:
        odo.append(float(tk), rng.normal(0.0, 0.1, 3), float(rng.uniform(0.0, 1e-4)))
    return odo, t


def test_anchored_odometry_batch_equals_time_by_time() -> None:
    rng = np.random.default_rng(3)
    odo, t = _odometry(rng)
    assert isinstance(odo, BatchCovariances)
    query = np.concatenate([t[100:300:3], [t[49], t[50], -1.0, t[-1] + 5.0]])
    assert pose_covariances(odo, query) is None  # no anchor covariance yet
    A = rng.normal(size=(3, 3))
    odo.set_anchor(float(t[-1]), np.zeros(3), A @ A.T)
    got = pose_covariances(odo, query)
    assert got is not None and got.shape == (query.size, 3, 3)
    for k, tk in enumerate(query):
        ref = odo.covariance(float(tk))
        assert ref is not None and np.array_equal(got[k], ref)


def test_smoothed_pose_source_batch_equals_time_by_time() -> None:
    rng = np.random.default_rng(4)
    nodes = NodeTable()
    for k in range(20):
        A = rng.normal(size=(3, 3))
        nodes.add_anchor(float(k), A @ A.T)
    current = np.diag([1.0, 2.0, 3.0])
    src = SmoothedPoseSource(nodes, OdometryChain(0.0), lambda: None, lambda: current)
    query = np.concatenate([rng.uniform(-2.0, 22.0, 50), np.arange(20.0)])
    got = pose_covariances(src, query)
    assert got is not None
    for k, tk in enumerate(query):
        assert np.array_equal(got[k], src.covariance(float(tk)))


def test_a_source_without_batch_is_asked_time_by_time() -> None:
    rng = np.random.default_rng(5)
    t = np.arange(10.0)
    A = rng.normal(size=(10, 3, 3))
    covs = A @ np.transpose(A, (0, 2, 1))  # covariances: a source's others are refused
    traj = Trajectory(t, rng.normal(size=(10, 3)), covs)
    assert isinstance(traj, PoseSource) and not isinstance(traj, BatchCovariances)
    got = pose_covariances(traj, [0.5, 3.0, 9.5])
    assert got is not None and np.array_equal(got, covs[[0, 3, 9]])
    assert pose_covariances(Trajectory(t, np.zeros((10, 3))), [1.0]) is None
