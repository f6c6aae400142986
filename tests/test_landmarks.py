"""The landmark layer shared by both back ends: duplicates of one wall merged by the joint
compatibility test, distinct walls kept apart, and the EKF's robust (kernel-weighted) update."""

from __future__ import annotations

import numpy as np
import pytest

from sonarslam.features.geometry import compose, inverse, line_world_to_frame, transform_points
from sonarslam.features.line import LineFeature
from sonarslam.slam.backends.ekf import EkfConfig, LineEkf
from sonarslam.slam.backends.isam2.graph import GraphConfig, LineIsam2
from sonarslam.slam.model.motion import motion_step
from sonarslam.sonar.beam import Mounting

R_LINE = np.diag([0.05**2, np.deg2rad(0.5) ** 2])


def _backend(kind: str, **settings: object) -> LineEkf | LineIsam2:
    """A back end at the origin. The vehicle of these tests stands still, so every view counts
    (``reobservation_min_move_m`` None) unless a test sets the limit itself."""
    settings.setdefault("reobservation_min_move_m", None)
    pose, P0 = np.zeros(3), np.diag([1e-4, 1e-4, 1e-6])
    if kind == "ekf":
        return LineEkf(0.0, pose, P0, Mounting(), EkfConfig(**settings))  # type: ignore[arg-type]
    return LineIsam2(0.0, pose, P0, Mounting(), GraphConfig(**settings))  # type: ignore[arg-type]


def _see(be: LineEkf | LineIsam2, t: float, walls: list[tuple[np.ndarray, np.ndarray]]) -> list:
    """One vote at time ``t`` from the (still) vehicle: each wall (world line, world ends)."""
    be.predict(motion_step(t - 0.5, t, np.zeros(2), 0.01, 0.0, t - 0.5))
    wTs = compose(be.pose, be.bTs)
    feats = []
    for line_w, ends_w in walls:
        z = line_world_to_frame(line_w, wTs)[0]
        ends_r = transform_points(inverse(wTs), ends_w)
        feats.append(LineFeature(t, wTs, float(z[0]), float(z[1]), R_LINE, 40, ends_r, 40))
    return be.update_lines(feats)


WALL = np.array([10.0, 0.0])  # x = 10


def _stretch(y0: float, y1: float) -> np.ndarray:
    return np.array([[10.0, y0], [10.0, y1]])


@pytest.mark.parametrize("kind", ["ekf", "isam2"])
def test_two_landmarks_of_one_wall_are_merged_when_their_extents_meet(kind: str) -> None:
    be = _backend(kind, merge_gate_probability=0.99)
    t = 1.0
    for stretch in ((-30.0, -20.0), (20.0, 30.0)):  # 40 m apart: beyond the extent gate
        for _ in range(2):  # a tentative line, then a landmark
            _see(be, t, [(WALL, _stretch(*stretch))])
            t += 1.0
    assert len(be.map.active()) == 2 and be.stats["merged"] == 0
    ids = _see(be, t, [(WALL, _stretch(-18.0, 15.0))])  # reaches both extents' margins
    assert ids[0] is not None
    assert be.stats["merged"] == 0  # found on the estimate after this vote's update: ...
    # ... which comes with the next vote, whose observations the merged wall takes, from
    # anywhere along it
    assert _see(be, t + 1.0, [(WALL, _stretch(22.0, 28.0))])[0] == 0
    assert be.stats["merged"] == 1 and len(be.map.active()) == 1
    (record,) = be.map_records()
    assert record["id"] == 0
    assert record["rho"] == pytest.approx(10.0, abs=0.05)
    assert record["observations"] == (4 if kind == "isam2" else 2) + 2
    ends = np.asarray(record["endpoints"])
    assert sorted(ends[:, 1].tolist()) == pytest.approx([-30.0, 30.0], abs=1.0)


@pytest.mark.parametrize("kind", ["ekf", "isam2"])
def test_a_parallel_wall_two_metres_behind_is_not_merged(kind: str) -> None:
    be = _backend(kind, merge_gate_probability=0.99)
    other = np.array([12.0, 0.0])  # x = 12, the same side, overlapping extents
    t = 1.0
    for _ in range(2):
        _see(be, t, [(WALL, _stretch(-10.0, 0.0)), (other, np.array([[12.0, 0.0], [12.0, 9.0]]))])
        t += 1.0
    for _ in range(3):
        _see(be, t, [(WALL, _stretch(-9.0, 1.0)), (other, np.array([[12.0, -2.0], [12.0, 8.0]]))])
        t += 1.0
    assert be.stats["merged"] == 0 and len(be.map.active()) == 2
    rhos = sorted(r["rho"] for r in be.map_records())
    assert rhos == pytest.approx([10.0, 12.0], abs=0.05)


def test_the_ekf_robust_update_bends_towards_an_outlier_by_less() -> None:
    """A line inside the association gate but ~2.5 sigma off a well-known wall moves the pose
    less with Huber (its covariance divided by the weight k/d) than without a kernel."""
    shifts = {}
    for robust in (None, "huber"):
        be = _backend("ekf", robust=robust)
        t = 1.0
        for _ in range(6):
            _see(be, t, [(WALL, _stretch(-10.0, 10.0))])
            t += 1.0
        x0 = be.pose[0]
        ids = _see(be, t, [(np.array([10.14, 0.0]), _stretch(-10.0, 10.0))])
        assert ids[0] is not None  # associated: inside the gate
        shifts[robust] = abs(be.pose[0] - x0)
    assert shifts[None] > 1e-3
    assert 0.2 * shifts[None] < shifts["huber"] < 0.8 * shifts[None]


@pytest.mark.parametrize("kind", ["ekf", "isam2"])
def test_reobservations_from_the_same_place_are_counted_once(kind: str) -> None:
    """With ``reobservation_min_move_m``, a still vehicle's repeated views of a wall are
    associated but only the first after the landmark's creation is used; without it all are."""
    walls = [(WALL, _stretch(-5.0, 5.0))]
    for limit, used in ((None, 6), (2.0, 0)):
        be = _backend(kind, tentative_observations=2, reobservation_min_move_m=limit)
        ids = [_see(be, float(t), walls)[0] for t in range(1, 9)]
        assert ids[2:] == [0] * 6  # associated every time after the two tentative views
        assert be.map.stats["associated"] - be.map.stats["reobservations_skipped"] == used
        assert be.map.stats["reobservations_skipped"] == 6 - used


@pytest.mark.parametrize("kind", ["ekf", "isam2"])
def test_the_far_face_of_a_breakwater_is_not_paired_with_the_near_one(kind: str) -> None:
    """A breakwater's two faces, x = 10 and x = 10.5, each seen from its own side: after 20 m of
    odometry (1 m of position sigma) the far face's line is inside the chi2 gate of the near
    face's landmark, and only the side gate, on by default in both back ends, keeps them apart
    (issue 31: the EKF without it paired such faces on drawn worlds)."""
    be = _backend(kind)
    near, far = np.array([10.0, 0.0]), np.array([10.5, 0.0])
    t = 1.0
    for _ in range(2):  # a tentative line, then a landmark: the near face, from x = 0
        _see(be, t, [(near, _stretch(-10.0, 10.0))])
        t += 1.0
    assert len(be.map.active()) == 1
    # drive to x = 20 along the breakwater's end, with a DVL sigma that leaves ~1 m
    be.predict(motion_step(t - 1.0, t + 40.0, np.array([0.5, 0.0]), 0.05, 0.0, t - 1.0))
    t += 41.0
    assert be.pose[0] == pytest.approx(20.5, abs=1e-9)
    ids = _see(be, t, [(far, np.array([[10.5, -10.0], [10.5, 10.0]]))])
    assert ids == [None]  # a tentative line of its own, not the near face's landmark
    assert be.map.stats["associated"] == 0
    unguarded = _backend(kind, side_gate=False)
    t = 1.0
    for _ in range(2):
        _see(unguarded, t, [(near, _stretch(-10.0, 10.0))])
        t += 1.0
    unguarded.predict(motion_step(t - 1.0, t + 40.0, np.array([0.5, 0.0]), 0.05, 0.0, t - 1.0))
    assert _see(unguarded, t + 41.0, [(far, np.array([[10.5, -10.0], [10.5, 10.0]]))]) == [0]
