"""One vote of lines is one call from a back end into the landmark layer and none back: a
profiler trace of a short run with both back ends counts the calls between the two packages."""

from __future__ import annotations

import cProfile
import os
import pstats
from pathlib import Path

import numpy as np
import pytest

from sonarslam.features.geometry import compose, inverse, line_world_to_frame, transform_points
from sonarslam.features.line import LineFeature
from sonarslam.slam.backends.ekf import EkfConfig, LineEkf
from sonarslam.slam.backends.isam2.graph import GraphConfig, LineIsam2
from sonarslam.slam.model.motion import motion_step
from sonarslam.sonar.beam import Mounting

ROOT = Path(__file__).resolve().parent.parent
MAPPING = str(ROOT / "slam" / "mapping")
BACKENDS = str(ROOT / "slam" / "backends")
R_LINE = np.diag([0.05**2, np.deg2rad(0.5) ** 2])
#: a 40 m x 30 m basin: (world line, its two world end points)
WALLS = [
    (np.array([20.0, 0.0]), np.array([[20.0, -15.0], [20.0, 15.0]])),
    (np.array([20.0, np.pi]), np.array([[-20.0, -15.0], [-20.0, 15.0]])),
    (np.array([15.0, np.pi / 2]), np.array([[-20.0, 15.0], [20.0, 15.0]])),
    (np.array([15.0, -np.pi / 2]), np.array([[-20.0, -15.0], [20.0, -15.0]])),
]


def _drive(be: LineEkf | LineIsam2, n_votes: int, seed: int) -> int:
    """Sail along x at 0.5 m/s, a vote of the four walls (noisy) every second; the votes."""
    rng = np.random.default_rng(seed)
    votes = 0
    for k in range(1, n_votes + 1):
        t = float(k)
        be.predict(motion_step(t - 1.0, t, np.array([0.5, 0.0]), 0.02, 0.0, t - 1.0))
        be.update_heading(t, 0.0)
        wTs = compose(np.array([0.5 * t - 10.0, 0.0, 0.0]), be.bTs)
        feats = []
        for line_w, ends_w in WALLS:
            z = line_world_to_frame(line_w, wTs)[0] + rng.normal(0.0, [0.05, 0.005])
            ends_r = transform_points(inverse(wTs), ends_w)
            feats.append(LineFeature(t, wTs, float(z[0]), float(z[1]), R_LINE, 40, ends_r, 40))
        be.update_lines(feats)
        votes += 1
    return votes


def _crossings(profile: cProfile.Profile) -> tuple[int, int]:
    """Calls ``(back ends -> landmark layer, landmark layer -> back ends)`` in the trace."""
    stats = pstats.Stats(profile).stats  # type: ignore[attr-defined]
    down = up = 0
    for (callee, _, _), (_, _, _, _, callers) in stats.items():
        callee_file = os.path.realpath(callee)  # sonarslam/slam is a link to slam/
        for (caller, _, _), (_, n_calls, _, _) in callers.items():
            caller_file = os.path.realpath(caller)
            if caller_file.startswith(BACKENDS) and callee_file.startswith(MAPPING):
                down += n_calls
            elif caller_file.startswith(MAPPING) and callee_file.startswith(BACKENDS):
                up += n_calls
    return down, up


@pytest.mark.parametrize("kind", ["ekf", "isam2"])
def test_one_vote_is_one_call_into_the_landmark_layer_and_none_back(kind: str) -> None:
    pose, P0 = np.array([-10.0, 0.0, 0.0]), np.diag([1e-2, 1e-2, 1e-4])
    be: LineEkf | LineIsam2
    if kind == "ekf":
        be = LineEkf(0.0, pose, P0, Mounting(), EkfConfig(reobservation_min_move_m=2.0))
    else:
        be = LineIsam2(0.0, pose, P0, Mounting(), GraphConfig(reobservation_min_move_m=2.0))
    profile = cProfile.Profile()
    profile.enable()
    votes = _drive(be, 20, seed=3)
    profile.disable()
    assert len(be.map.active()) == 4  # the four walls are landmarks, observed again
    assert be.stats["associated"] >= 4 * (votes - 2)
    assert _crossings(profile) == (votes, 0)
