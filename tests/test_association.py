"""Data association on hand-made problems with known answers."""

from __future__ import annotations

import numpy as np
import pytest

from sonarslam.features.geometry import line_difference
from sonarslam.slam.mapping.association import (
    AssociationConfig,
    AssociationProblem,
    associate,
    individual_compatibility,
)


def problem_with(z, z_hat, sigma_obs=0.1, sigma_state=0.05):
    z = np.asarray(z, float)
    z_hat = np.asarray(z_hat, float)
    k = len(z_hat)
    d = 2 * k
    H = np.zeros((k, 2, d))
    for j in range(k):
        H[j, :, 2 * j : 2 * j + 2] = np.eye(2)
    R = np.tile(np.diag([sigma_obs**2, np.deg2rad(1.0) ** 2]), (len(z), 1, 1))
    return AssociationProblem(z, R, z_hat, H, np.eye(d) * sigma_state**2)


def test_innovation_handles_the_sign_ambiguity_near_rho_zero():
    nu, flipped = line_difference(np.array([0.05, 0.0]), np.array([0.02, -np.pi + 0.01]))
    assert flipped
    assert np.allclose(nu, [-0.05 - 0.02, -0.01], atol=1e-12)
    nu, flipped = line_difference(np.array([5.0, 3.1]), np.array([5.1, -3.1]))
    assert not flipped and np.allclose(nu, [-0.1, 6.2 - 2 * np.pi], atol=1e-12)


@pytest.mark.parametrize("method", ["nn", "jcbb"])
def test_finds_the_true_pairing_and_rejects_clutter(method):
    rng = np.random.default_rng(4)
    lm = np.array([[10.0, 0.3], [12.0, 1.9], [25.0, -1.2], [8.0, -2.8]])
    truth = [2, 0, None, 3]
    z = []
    for j in truth:
        if j is None:
            z.append([40.0, 0.9])  # clutter: far from every landmark
        else:
            z.append(lm[j] + rng.normal(0, [0.08, np.deg2rad(0.8)]))
    out = associate(problem_with(z, lm), AssociationConfig(method=method))
    assert out == truth


def test_jcbb_resolves_what_nearest_neighbour_gets_wrong():
    # Two parallel landmarks 0.6 m apart; the vehicle's own shift (common to both observations
    # through the state) makes each observation individually nearest to the wrong landmark.
    lm = np.array([[10.0, 0.0], [10.6, 0.0], [20.0, 1.5]])
    d = 3
    H = np.zeros((3, 2, d))
    H[:, 0, 0] = -np.cos(lm[:, 1])  # rho of every landmark moves with the vehicle's x (state 0)
    H[:, 1, 2] = 1.0
    P = np.diag([0.5**2, 1e-6, 1e-6])
    shift = 0.45
    z = np.array([[10.0 - shift, 0.0], [10.6 - shift, 0.0], [20.0 - shift * np.cos(1.5), 1.5]])
    R = np.tile(np.diag([0.05**2, np.deg2rad(0.5) ** 2]), (3, 1, 1))
    p = AssociationProblem(z, R, lm, H, P)
    assert associate(p, AssociationConfig(method="jcbb")) == [0, 1, 2]
    d2, _, _ = individual_compatibility(p)
    assert d2[1, 0] < d2[1, 1]  # individually, observation 1 is nearer landmark 0
    assert associate(p, AssociationConfig(method="nn")) != [0, 1, 2]


def test_empty_inputs():
    p = problem_with(np.zeros((0, 2)), [[1.0, 0.0]])
    assert associate(p, AssociationConfig()) == []
    p = problem_with([[1.0, 0.0]], np.zeros((0, 2)))
    assert associate(p, AssociationConfig()) == [None]


def test_config_is_checked():
    with pytest.raises(ValueError, match="method must be one of 'jcbb', 'nn', got 'hungarian'"):
        AssociationConfig(method="hungarian")
    with pytest.raises(ValueError, match=r"gate_probability must be in \(0, 1\), got 1"):
        AssociationConfig(gate_probability=1.0)


@pytest.fixture(scope="module")
def harbour_ekf(opened):
    """300 s of simulated harbour (seed 4) and the EKF closed loop on it with the default
    settings: (dataset, result), run once for the module's two tests of it."""
    from sonarslam.features.config import ExtractorConfig
    from sonarslam.slam.backends.ekf import EkfConfig, LineEkf
    from sonarslam.slam.run.closed_loop import run_closed_loop

    ds = opened("harbour", 4, 300.0)
    mount = ds.config.sonar_mounting
    res = run_closed_loop(
        ds, lambda t, p, P: LineEkf(t, p, P, mount, EkfConfig()), ExtractorConfig(), progress=False
    )
    return ds, res


def test_ekf_closed_loop_associates_the_true_walls(harbour_ekf):
    """EKF closed loop on 300 s of simulated harbour: the pairings against the true walls meet
    the issue's targets (precision 99 %, recall 95 %), and the tentative lines that seeded
    landmarks are reported as seeds, on their landmark's wall."""
    from sonarslam.slam.eval.truth import (
        association_against_truth,
        landmark_overshoot_m,
        truth_walls,
    )

    ds, res = harbour_ekf
    walls = truth_walls(ds)
    s = association_against_truth(ds, res.features, res.feature_landmarks, res.feature_seeds)
    # with the default rule (a landmark needs 2 sightings) each landmark has one seed
    assert s.n_seeds == len(res.backend.map) >= 3
    assert s.n_associated >= 20
    assert s.precision >= 0.99 and s.recall >= 0.95 and s.seed_precision == 1.0
    assert landmark_overshoot_m(res.backend.map_records(), walls).max() < 12.0


@pytest.mark.parametrize("method", ["jcbb", "nn"])
def test_a_pairing_ruled_out_by_the_back_end_is_never_made(method):
    """``allowed`` (e.g. the landmark's extent) overrides a perfect Mahalanobis match."""
    from sonarslam.slam.mapping.association import AssociationConfig, AssociationProblem, associate

    z = np.array([[5.0, 0.1], [8.0, 1.2]])
    R = np.broadcast_to(np.diag([0.01, 1e-4]), (2, 2, 2)).copy()
    z_hat = z.copy()  # each observation matches its landmark exactly
    H = np.zeros((2, 2, 3))
    P = np.eye(3)
    cfg = AssociationConfig(method=method)
    assert associate(AssociationProblem(z, R, z_hat, H, P), cfg) == [0, 1]
    allowed = np.array([[False, True], [True, True]])
    assert associate(AssociationProblem(z, R, z_hat, H, P, allowed), cfg) == [None, 1]


@pytest.mark.parametrize("backend", ["ekf", "isam2"])
def test_a_line_seen_in_both_representations_gets_the_extent_it_was_seen_over(backend):
    """A wall through the origin's neighbourhood (x = 0.05 m) is seen once as (rho, 0) and
    once as (rho', pi): their along-line axes are reversed. The landmark's extent must be the
    10 m stretch both saw, not their mirror images joined (40 m)."""
    from sonarslam.features.geometry import compose, inverse, line_world_to_frame, transform_points
    from sonarslam.features.line import LineFeature
    from sonarslam.slam.backends.ekf import EkfConfig, LineEkf
    from sonarslam.slam.backends.isam2.graph import GraphConfig, LineIsam2
    from sonarslam.slam.model.motion import motion_step
    from sonarslam.sonar.beam import Mounting

    pose = np.array([-8.0, 15.0, 0.0])
    P0 = np.diag([1e-4, 1e-4, 1e-6])
    mount = Mounting()
    if backend == "ekf":
        be = LineEkf(0.0, pose, P0, mount, EkfConfig())
    else:
        be = LineIsam2(0.0, pose, P0, mount, GraphConfig())
    wTs = compose(pose, mount.as_pose())
    ends_w = np.array([[0.05, 10.0], [0.05, 20.0]])
    ids = []
    for k, line_w in enumerate((np.array([0.05, 0.0]), np.array([0.05, np.pi]))):
        z = line_world_to_frame(line_w, wTs)[0]
        f = LineFeature(
            t=0.1 * (k + 1),
            wTr=wTs,
            rho_m=float(z[0]),
            theta_rad=float(z[1]),
            cov=np.diag([0.05**2, np.deg2rad(1.0) ** 2]),
            votes=30,
            endpoints_r=transform_points(inverse(wTs), ends_w),
        )
        be.predict(motion_step(0.1 * k, f.t, np.zeros(2), 0.01, 0.0, 0.1 * k))
        ids.extend(be.update_lines([f]))
    assert ids[0] is None and ids[1] is not None  # tentative, then the landmark
    (record,) = be.map_records()
    length = float(np.linalg.norm(np.subtract(*record["endpoints"])))
    assert length == pytest.approx(10.0, abs=0.5)


def test_the_extent_gate_keeps_a_landmark_within_its_longest_extent():
    """A wall along y = 5 (line (5, pi/2), along-line axis -x) whose landmark spans x in
    [0, 30]: a segment at x in [35, 45] reaches it within a 10 m margin; with a 40 m limit the
    grown extent (45 m) is too long, and a segment at x in [20, 38] (grown 38 m) is not; a
    segment of 50 m alone may join (no landmark is cut shorter than one observation)."""
    from sonarslam.features.geometry import along_line
    from sonarslam.slam.mapping.association import extent_allowed

    line = np.array([[5.0, np.pi / 2]])
    s = along_line(line[0], np.array([[0.0, 5.0], [30.0, 5.0]]))
    extent = np.array([[s.min(), s.max()]])
    segments = np.array(
        [
            [[35.0, 5.0], [45.0, 5.0]],
            [[20.0, 5.0], [38.0, 5.0]],
            [[-10.0, 5.0], [40.0, 5.0]],
            [[60.0, 5.0], [70.0, 5.0]],
        ]
    )
    assert extent_allowed(line, extent, segments, 10.0)[:, 0].tolist() == [True] * 3 + [False]
    limited = extent_allowed(line, extent, segments, 10.0, max_extent_m=40.0)
    assert limited[:, 0].tolist() == [False, True, True, False]
    # without the margin gate only the length limits
    assert extent_allowed(line, extent, segments, None, 40.0)[:, 0].tolist() == [
        False,
        True,
        True,
        False,
    ]


def test_a_landmark_longer_than_its_limit_is_not_made_by_the_loop(harbour_ekf):
    """EKF closed loop on 300 s of simulated harbour (seed 4): with ``max_extent_m = 20`` no
    landmark's extent is longer than 20 m beyond what a single observation spans, and more
    landmarks stand for the same walls than without the limit."""
    from dataclasses import replace

    from sonarslam.features.config import ExtractorConfig
    from sonarslam.slam.backends.ekf import EkfConfig, LineEkf
    from sonarslam.slam.run.closed_loop import run_closed_loop

    ds, default = harbour_ekf
    mount = ds.config.sonar_mounting
    assert EkfConfig().max_extent_m is None  # the module's default run is the one without limit
    lengths = {
        None: [
            float(np.linalg.norm(np.subtract(*r["endpoints"])))
            for r in default.backend.map_records()
        ]
    }
    for limit in (20.0,):
        cfg = replace(EkfConfig(), max_extent_m=limit)
        res = run_closed_loop(
            ds, lambda t, p, P, c=cfg: LineEkf(t, p, P, mount, c), ExtractorConfig(), progress=False
        )
        lengths[limit] = [
            float(np.linalg.norm(np.subtract(*r["endpoints"]))) for r in res.backend.map_records()
        ]
    longest_segment_m = 15.0  # the extractor's segments on this world: at most ~the range
    assert max(lengths[None]) > 20.0 + longest_segment_m
    assert max(lengths[20.0]) <= 20.0 + longest_segment_m
    assert len(lengths[20.0]) > len(lengths[None])
