"""The public API: ``import sonarslam`` is light and names what a user needs, each documented;
the association for a SLAM of one's own refuses a skipped step; GTSAM's local-frame marginals
are converted to world coordinates by one function, checked against GTSAM's own retract."""

from __future__ import annotations

import ast
import importlib
import inspect
import json
import subprocess
import sys
from collections.abc import Callable
from dataclasses import replace
from pathlib import Path

import gtsam
import numpy as np
import pytest
from gtsam.symbol_shorthand import L, X

import sonarslam
from sonarslam.datasets.source import open_dataset
from sonarslam.features.geometry import (
    compose,
    inverse,
    line_difference,
    line_world_to_frame,
    transform_points,
)
from sonarslam.features.line import LineFeature
from sonarslam.settings import SettingError
from sonarslam.slam.backends.isam2.config import GraphConfig
from sonarslam.slam.backends.isam2.factors import line_factor
from sonarslam.slam.mapping.landmarks import LandmarkConfig, LandmarkMap
from sonarslam.slam.mapping.plugin import LandmarkAssociation, WorldBelief, gtsam_belief
from sonarslam.slam.mapping.vote import Belief, LandmarkBelief
from sonarslam.slam.model.lines import local_to_world, local_to_world_covariance
from sonarslam.slam.run.presets import RunConfig, extractor_config, extractor_preset
from sonarslam.slam.run.run import run_backend

ROOT = Path(__file__).resolve().parent.parent
#: Packages ``import sonarslam`` must not load (seconds of imports and JIT caches).
HEAVY = ("gtsam", "numba", "matplotlib", "scipy", "pandas", "dask", "evo", "shapely")
BTS = np.array([0.3, 0.0, np.pi])
R_LINE = np.diag([0.05**2, np.deg2rad(0.5) ** 2])
#: a 40 m x 30 m basin: (world line, its two world end points)
WALLS = [
    (np.array([20.0, 0.0]), np.array([[20.0, -15.0], [20.0, 15.0]])),
    (np.array([20.0, np.pi]), np.array([[-20.0, -15.0], [-20.0, 15.0]])),
    (np.array([15.0, np.pi / 2]), np.array([[-20.0, 15.0], [20.0, 15.0]])),
    (np.array([15.0, -np.pi / 2]), np.array([[-20.0, -15.0], [20.0, -15.0]])),
]


# -- the names ---------------------------------------------------------------------------------


def test_import_sonarslam_loads_no_heavy_package() -> None:
    code = "import json, sys, sonarslam; print(json.dumps(sorted(sys.modules)))"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    loaded = set(json.loads(out.stdout))
    assert "sonarslam" in loaded
    heavy = [m for m in loaded if m.split(".")[0] in HEAVY]
    assert heavy == [], heavy
    layers = [m for m in loaded if m.startswith("sonarslam.")]
    assert layers == [], layers


def _type_checking_homes() -> dict[str, str]:
    """Name -> module of the ``if TYPE_CHECKING:`` imports of ``sonarslam/__init__.py``."""
    tree = ast.parse((ROOT / "sonarslam" / "__init__.py").read_text())
    block = next(n for n in tree.body if isinstance(n, ast.If))
    assert ast.unparse(block.test) == "TYPE_CHECKING"
    return {
        alias.name: node.module
        for node in block.body
        if isinstance(node, ast.ImportFrom) and node.module
        for alias in node.names
    }


def test_the_public_names_are_one_table() -> None:
    homes = sonarslam._HOMES
    assert sonarslam.__all__ == sorted(sonarslam.__all__)
    assert set(sonarslam.__all__) == set(homes)
    assert _type_checking_homes() == homes  # what mypy sees is what is loaded
    assert set(dir(sonarslam)) == {*sonarslam.__all__, "__version__"}  # not its own imports
    with pytest.raises(AttributeError, match="no attribute 'Trajectory'"):
        _ = sonarslam.Trajectory


def test_the_version_is_the_installed_distributions() -> None:
    from importlib.metadata import version

    assert sonarslam.__version__ == version("sonarslam")
    assert sonarslam.__version__.count(".") >= 1


@pytest.mark.parametrize("name", sonarslam.__all__)
def test_every_public_name_resolves_to_a_documented_object(name: str) -> None:
    obj = getattr(sonarslam, name)
    home = importlib.import_module(sonarslam._HOMES[name])
    assert getattr(home, name) is obj
    assert not name.startswith("_") and name in getattr(home, "__all__", [name])
    doc = inspect.getdoc(obj) or ""
    assert len(doc) >= 60, f"{name}: {doc!r}"
    if inspect.isclass(obj) and not getattr(obj, "_is_protocol", False):
        assert "Attributes" in doc or "Parameters" in doc, name
    if inspect.isclass(obj) and getattr(obj, "_is_protocol", False):
        methods = [m for m in vars(obj) if not m.startswith("_") and callable(vars(obj)[m])]
        assert methods and all(inspect.getdoc(getattr(obj, m)) for m in methods), name
        return
    params = inspect.signature(obj).parameters.values()
    named = [
        p.name
        for p in params
        if p.name != "self" and p.kind not in (p.VAR_POSITIONAL, p.VAR_KEYWORD)
    ]
    missing = [p for p in named if p not in doc]
    assert missing == [], f"{name} does not document {missing}"


# -- GTSAM's local frame -----------------------------------------------------------------------


def _retract_xyyaw(wTb: np.ndarray, xi: np.ndarray) -> np.ndarray:
    p = gtsam.Pose2(*wTb).retract(xi)
    return np.array([p.x(), p.y(), p.theta()])


def test_local_to_world_covariance_is_gtsams_retract_to_first_order() -> None:
    rng = np.random.default_rng(5)
    wTb = np.array([3.0, -2.0, 2.4])
    A = rng.normal(size=(5, 5))
    C = A @ A.T * 1e-4  # [pose in the local tangent, a line]
    W = local_to_world_covariance(wTb, C)
    # the Jacobian of xi -> (x, y, yaw) of wTb.retract(xi), by central differences
    eps = 1e-6
    J = np.column_stack(
        [
            (_retract_xyyaw(wTb, eps * e) - _retract_xyyaw(wTb, -eps * e)) / (2 * eps)
            for e in np.eye(3)
        ]
    )
    T = np.eye(5)
    T[:3, :3] = J
    np.testing.assert_allclose(W, T @ C @ T.T, rtol=1e-7, atol=1e-12)
    np.testing.assert_array_equal(W[3:, 3:], C[3:, 3:])  # a vector's tangent is the world's
    # and the spread of poses drawn in GTSAM's tangent, seen in the world (seeded)
    xi = rng.multivariate_normal(np.zeros(3), C[:3, :3], size=20000)
    world = np.array([_retract_xyyaw(wTb, x) for x in xi])
    np.testing.assert_allclose(np.cov(world.T), W[:3, :3], rtol=0.05, atol=2e-7)
    with pytest.raises(ValueError, match="cov_local"):
        local_to_world_covariance(wTb, np.eye(2))


def _four_landmarks(wTb: np.ndarray) -> tuple[LandmarkAssociation, np.ndarray]:
    """An association that made the four walls landmarks 0..3 from ``wTb`` (two votes), and
    their world lines (4, 2)."""
    rng = np.random.default_rng(8)
    assoc = LandmarkAssociation(BTS, seeds_used=True)
    assoc.decide(_vote(1.0, wTb, rng), _belief(wTb, []))
    assoc.applied(_belief(wTb, []))
    decision = assoc.decide(_vote(2.0, wTb, rng), _belief(wTb, []))
    lines_w = np.array([new.line_w for new in decision.new_landmarks])
    assoc.applied(_belief(wTb, list(lines_w)))
    assert len(assoc.map.landmarks) == 4
    return assoc, lines_w


def test_gtsam_belief_reads_isam2_and_marginals_by_key_in_world_coordinates() -> None:
    rng = np.random.default_rng(7)
    graph, values = gtsam.NonlinearFactorGraph(), gtsam.Values()
    wTb = np.array([2.0, 1.0, 0.7])
    assoc, lines_w = _four_landmarks(wTb)
    C = np.diag([0.04, 0.09, 0.01])
    graph.add(
        gtsam.PriorFactorPose2(X(0), gtsam.Pose2(*wTb), gtsam.noiseModel.Gaussian.Covariance(C))
    )
    values.insert(X(0), gtsam.Pose2(*wTb))
    for j in (3, 2, 1, 0):  # inserted in the other order than the ids
        line_w = lines_w[j]
        wTs = compose(wTb, BTS)
        z = line_world_to_frame(line_w, wTs)[0] + rng.normal(0.0, [0.05, 0.01])
        graph.add(line_factor(X(0), L(j), z, R_LINE, BTS))
        graph.add(gtsam.PriorFactorVector(L(j), line_w, gtsam.noiseModel.Isotropic.Sigma(2, 1.0)))
        values.insert(L(j), line_w)
    isam = gtsam.ISAM2()
    isam.update(graph, values)
    estimate = isam.calculateEstimate()
    b = gtsam_belief(estimate, X(0), L, assoc, isam)  # landmark j at L(j), in the ids' order
    assert b.k == 4
    marginals = gtsam.Marginals(graph, estimate)  # relinearised at the estimate: not iSAM2's
    batch = gtsam_belief(estimate, X(0), L, assoc, marginals)
    np.testing.assert_allclose(
        batch.cov[:3, :3],
        local_to_world_covariance(batch.wTb, marginals.marginalCovariance(X(0))),
        rtol=1e-9,
    )
    np.testing.assert_allclose(batch.cov[5:7, 5:7], marginals.marginalCovariance(L(1)), rtol=1e-9)
    np.testing.assert_allclose(batch.cov, b.cov, rtol=0.05, atol=1e-4)
    p = estimate.atPose2(X(0))
    np.testing.assert_allclose(b.wTb, [p.x(), p.y(), p.theta()])
    for j in range(4):
        np.testing.assert_allclose(b.lines_w[j], estimate.atVector(L(j)))
    local = isam.marginalCovariance(X(0))
    np.testing.assert_allclose(b.cov[:3, :3], local_to_world_covariance(b.wTb, local), rtol=1e-9)
    np.testing.assert_allclose(b.cov[3:5, 3:5], isam.marginalCovariance(L(0)), rtol=1e-9)
    cross = isam.jointMarginalCovariance([X(0), L(1)]).at(X(0), L(1))
    T = local_to_world(float(b.wTb[2]))  # landmark 1: columns 5:7
    np.testing.assert_allclose(b.cov[:3, 5:7], T @ cross, rtol=1e-9, atol=1e-15)
    assert np.abs(b.cov[:3, 3:]).max() > 1e-6  # the lines are correlated with the pose
    assert gtsam_belief(estimate, X(0), L, assoc).cov is None
    keys = [L(j) for j in reversed(range(4))]  # a list of keys could be in any order: refused
    with pytest.raises(TypeError, match=r"line_key=...\) must be the function .* got list"):
        gtsam_belief(estimate, X(0), keys, assoc)  # type: ignore[arg-type]


def test_a_belief_in_another_order_than_the_ids_is_refused() -> None:
    """The docs' iSAM2 example given its landmark keys reversed made 7 landmarks for 3 walls
    (5 duplicates, one ~79 off), without a word: each line was taken for another's. A belief's
    row j that moved since the last decide beyond any consistent update is now refused by
    decide and applied, naming the row; a smoother's move of a few standard deviations (a loop
    closure) still passes."""
    wTb = np.array([-10.0, 0.0, 0.0])
    rng = np.random.default_rng(9)
    assoc, lines_w = _four_landmarks(wTb)
    reversed_lines = list(lines_w[::-1])
    with pytest.raises(ValueError, match=r"decide: belief.lines_w row 0 .* is not landmark 0"):
        assoc.decide(_vote(3.0, wTb, rng), _belief(wTb, reversed_lines))
    assoc.decide(_vote(3.0, wTb, rng), _belief(wTb, list(lines_w)))
    with pytest.raises(ValueError, match=r"applied: belief.lines_w row 0 .* another order"):
        assoc.applied(_belief(wTb, reversed_lines))
    # a loop closure moving every line by 5 standard deviations (rho 10 cm, theta 0.57 deg)
    moved = lines_w + np.array([5 * 0.1, 5 * 0.01])
    assoc.applied(_belief(wTb, list(moved)))
    decision = assoc.decide(_vote(4.0, wTb, rng), _belief(wTb, list(moved)))
    assert len(decision.new_landmarks) == 0
    # two landmarks swapped: the walls 40 m apart
    swapped = moved[[1, 0, 2, 3]]
    with pytest.raises(ValueError, match=r"row 0 .* is not landmark 0"):
        assoc.applied(_belief(wTb, list(swapped)))


# -- the association for one's own SLAM --------------------------------------------------------


def _vote(
    t: float, wTb: np.ndarray, rng: np.random.Generator, bTs: np.ndarray | None = None
) -> list[LineFeature]:
    """The four walls seen (noisy) from body pose ``wTb`` by the sonar at :data:`BTS`; the
    lines carry ``bTs`` as their mounting (None: none, as a line made by hand)."""
    wTs = compose(wTb, BTS)
    out = []
    for line_w, ends_w in WALLS:
        z = line_world_to_frame(line_w, wTs)[0] + rng.normal(0.0, [0.05, 0.005])
        ends_r = transform_points(inverse(wTs), ends_w)
        out.append(LineFeature(t, wTs, float(z[0]), float(z[1]), R_LINE, 40, ends_r, 40, bTs))
    return out


def _belief(wTb: np.ndarray, lines_w: list[np.ndarray]) -> WorldBelief:
    """An estimate that knows the pose to a centimetre and each landmark to 10 cm."""
    k = len(lines_w)
    cov = np.diag([1e-4, 1e-4, 1e-6] + [1e-2, 1e-4] * k)
    return WorldBelief(wTb, np.array(lines_w).reshape(-1, 2), cov)


def test_the_association_finds_each_wall_once_when_every_step_is_taken() -> None:
    rng = np.random.default_rng(3)
    assoc = LandmarkAssociation(BTS, seeds_used=False)
    lines_w: list[np.ndarray] = []
    updates = 0
    for k in range(1, 31):
        wTb = np.array([0.5 * k - 10.0, 0.0, 0.0])
        decision = assoc.decide(_vote(float(k), wTb, rng), _belief(wTb, lines_w))
        updates += len(decision.updates)
        lines_w += [new.line_w for new in decision.new_landmarks]
        assoc.applied(_belief(wTb, lines_w))
    assert len(lines_w) == 4  # the four walls, each once
    for truth, _ in WALLS:
        near = [
            j
            for j, line in enumerate(lines_w)
            if np.abs(line_difference(line, truth)[0]).max() < 0.2
        ]
        assert len(near) == 1, (truth, lines_w)
    assert updates >= 4 * 2  # re-observed every 5 m of the 15 m sailed
    assert [lm.s_max_m - lm.s_min_m > 20.0 for lm in assoc.map.landmarks] == [True] * 4


def test_a_skipped_step_is_refused_by_name() -> None:
    rng = np.random.default_rng(4)
    assoc = LandmarkAssociation(BTS, seeds_used=True)
    wTb = np.array([-10.0, 0.0, 0.0])
    assoc.decide(_vote(1.0, wTb, rng), _belief(wTb, []))
    with pytest.raises(RuntimeError, match=r"applied\(belief\)"):  # applied() forgotten
        assoc.decide(_vote(2.0, wTb, rng), _belief(wTb, []))
    assoc.applied(_belief(wTb, []))
    decision = assoc.decide(_vote(2.0, wTb, rng), _belief(wTb, []))
    assert len(decision.new_landmarks) == 4  # the second sighting promotes them
    with pytest.raises(ValueError, match="belief.lines_w holds 0 .* made 4"):  # not added
        assoc.applied(_belief(wTb, []))
    lines_w = [new.line_w for new in decision.new_landmarks]
    assert all(len(new.observations) == 2 for new in decision.new_landmarks)
    assoc.applied(_belief(wTb, lines_w))
    with pytest.raises(ValueError, match="belief.cov is None"):
        assoc.decide(_vote(3.0, wTb, rng), WorldBelief(wTb, np.array(lines_w)))
    with pytest.raises(ValueError, match=r"WorldBelief.cov must be \(11, 11\)"):
        WorldBelief(wTb, np.array(lines_w), np.eye(3))
    with pytest.raises(RuntimeError, match="no decision"):
        assoc.applied(_belief(wTb, lines_w))


def _landmarks(assoc: LandmarkAssociation, bTs: np.ndarray | None) -> list[np.ndarray]:
    """The world lines the association makes over 10 votes along x, lines carrying ``bTs``."""
    rng = np.random.default_rng(6)
    lines_w: list[np.ndarray] = []
    for k in range(1, 11):
        wTb = np.array([0.5 * k - 10.0, 0.0, 0.0])
        decision = assoc.decide(_vote(float(k), wTb, rng, bTs), _belief(wTb, lines_w))
        lines_w += [new.line_w for new in decision.new_landmarks]
        assoc.applied(_belief(wTb, lines_w))
    return lines_w


def test_a_mounting_other_than_the_extractors_is_refused_by_name() -> None:
    """The lines were extracted with the sonar at BTS; a plug-in given another mounting put
    every landmark off its wall without a word (lines without their mounting still do). The
    lines now carry it: the association, world_observation and line_factor refuse another,
    naming the parameter and both mountings, and line_factor takes it from the line."""
    wrong = BTS + np.array([0.0, 0.5, 0.0])  # a lever arm 0.5 m off to the side
    silent = _landmarks(LandmarkAssociation(wrong, seeds_used=False), bTs=None)
    off = np.array([min(np.abs(line_difference(lw, t)[0][0]) for t, _ in WALLS) for lw in silent])
    assert len(silent) == 4 and np.count_nonzero(off > 0.4) == 2, off  # the walls along x
    right = _landmarks(LandmarkAssociation(BTS, seeds_used=False), bTs=BTS)
    assert len(right) == 4
    assoc = LandmarkAssociation(wrong, seeds_used=False)
    wTb = np.array([-10.0, 0.0, 0.0])
    lines = _vote(1.0, wTb, np.random.default_rng(7), BTS)
    msg = r"sonar mounting bTs \[0.3   , 0.5   , 3.1416\] .* extracted with, \[0.3   , 0.    , 3.1416\]"
    with pytest.raises(ValueError, match=r"LandmarkAssociation\(bTs=...\): " + msg):
        assoc.decide(lines, _belief(wTb, []))
    with pytest.raises(ValueError, match=r"world_observation\(bTs=...\): " + msg):
        sonarslam.world_observation(lines[0], wTb, np.eye(3) * 1e-4, wrong)
    with pytest.raises(ValueError, match=r"line_factor\(bTs=...\): " + msg):
        line_factor(X(0), L(0), lines[0], bTs=wrong)
    # the line's own mounting, covariance and z: the same factor as given one by one
    values = gtsam.Values()
    values.insert(X(0), gtsam.Pose2(*wTb))
    values.insert(L(0), WALLS[0][0])
    own = line_factor(X(0), L(0), lines[0]).unwhitenedError(values)
    given = line_factor(X(0), L(0), lines[0].z, R_LINE, BTS).unwhitenedError(values)
    np.testing.assert_array_equal(own, given)
    with pytest.raises(TypeError, match="cov and bTs are required"):
        line_factor(X(0), L(0), lines[0].z)


def test_a_belief_in_degrees_is_refused_by_name() -> None:
    """A yaw or a line's theta beyond 2 pi is degrees given for radians: refused, naming the
    field; a covariance that is not one likewise. (A yaw of 90 "degrees" was taken as 90 rad
    and changed how many landmarks the association made.)"""
    lines_w = np.array([[5.0, 0.5], [3.0, -2.0]])
    cov = np.eye(7)
    assert WorldBelief(np.array([1.0, 2.0, 2.0 * np.pi]), lines_w, cov).k == 2
    with pytest.raises(ValueError, match=r"WorldBelief.wTb's yaw must be in radians .* 90\.0"):
        WorldBelief(np.array([1.0, 2.0, 90.0]), lines_w, cov)
    with pytest.raises(ValueError, match=r"lines_w's theta must be in radians .* 45\.0 at row 1"):
        WorldBelief(np.array([1.0, 2.0, 0.5]), np.array([[5.0, 0.5], [3.0, 45.0]]), cov)
    skew = np.eye(7)
    skew[0, 1] = 0.5
    with pytest.raises(ValueError, match="WorldBelief.cov must be a covariance"):
        WorldBelief(np.array([1.0, 2.0, 0.5]), lines_w, skew)
    with pytest.raises(ValueError, match="WorldBelief.cov must be a covariance"):
        WorldBelief(np.array([1.0, 2.0, 0.5]), lines_w, -np.eye(7))


def test_a_mounting_yaw_in_degrees_is_refused_by_the_line_model() -> None:
    """The docs' EKF example with the mounting's yaw given as 180 (degrees) to line_prediction
    made 7 landmarks for 3 walls (2 duplicates) without a word; the line model now refuses a
    yaw beyond 2 pi, naming the parameter, as WorldBelief does."""
    wTb = np.array([1.0, 2.0, 0.3])
    line_w = WALLS[0][0]
    z, H_pose, H_line = sonarslam.line_prediction(wTb, line_w, BTS)
    d = line_difference(z, line_world_to_frame(line_w, compose(wTb, BTS))[0])[0]
    np.testing.assert_allclose(d, 0.0, atol=1e-12)
    degrees = np.array([BTS[0], BTS[1], 180.0])
    msg = r"line_prediction\(bTs=...\): .* yaw must be in radians .* got 180.0"
    with pytest.raises(ValueError, match=msg):
        sonarslam.line_prediction(wTb, line_w, degrees)
    with pytest.raises(ValueError, match=r"mounting must be 3 finite numbers"):
        sonarslam.line_prediction(wTb, line_w, BTS[:2])
    with pytest.raises(ValueError, match=r"LandmarkAssociation\(bTs=...\): .* got 180.0"):
        LandmarkAssociation(degrees, seeds_used=False)


def test_a_beam_of_float_intensities_is_refused_by_name() -> None:
    """Intensities 0-1 as floats (an image normalised) gave the front end no line and no
    word; a beam refuses any dtype but uint8, by the rule dataset_from_arrays uses."""
    sim = sonarslam.simulate_records(sonarslam.make_scenario("harbour", seed=0, duration_s=30.0))
    extractor = sonarslam.LineExtractor(
        sonarslam.extractor_preset("default"),
        sim.scenario.head,
        sim.scenario.sonar_mounting,
        sim.trajectory,
    )
    beams = sim.beams
    assert sum(len(extractor.add(b)) for b in beams) > 0  # the uint8 beams give lines
    b = beams[0]
    msg = r"SonarBeam.intensities must be uint8 echo strengths 0-255, got float64 \(floats"
    with pytest.raises(ValueError, match=msg):
        sonarslam.SonarBeam(b.t, b.transducer_angle_rad, b.intensities / 255.0)
    with pytest.raises(ValueError, match=r"got int64 \(x.astype\(np.uint8\)"):
        sonarslam.SonarBeam(b.t, b.transducer_angle_rad, b.intensities.astype(np.int64))


def test_line_feature_documents_its_measurement() -> None:
    from sonarslam.features.line import LineFeature

    doc = inspect.getdoc(LineFeature) or ""
    assert "z : ndarray, shape (2,)" in doc and "``(rho_m, theta_rad)``" in doc


def test_the_landmark_layer_refuses_a_missing_after_previous() -> None:
    """The trial's duplicate: a back end that passed ``after_previous=None`` after a vote got
    a fifth landmark for four walls; the layer now names the parameter instead."""
    rng = np.random.default_rng(5)
    layer = LandmarkMap(LandmarkConfig(), BTS)
    wTb = np.array([-10.0, 0.0, 0.0])

    def belief(t: float) -> Belief:
        feats = _vote(t, wTb, rng)
        z = np.array([f.z for f in feats])
        R = np.array([f.cov for f in feats])
        return Belief(
            feats,
            0,
            z,
            R,
            wTb,
            np.eye(3) * 1e-4,
            None,
            [],
            np.zeros((0, 2)),
            np.zeros((0, 2, 3)),
            np.eye(3) * 1e-4,
            LandmarkBelief({}),
            False,
            None,
        )

    layer.vote(belief(1.0))
    with pytest.raises(ValueError, match=r"Belief.after_previous is None, but the vote at t=1.000"):
        layer.vote(belief(2.0))


# -- a run with a typed configuration -----------------------------------------------------------


def test_run_backend_takes_a_typed_config(simulated: Callable[..., Path]) -> None:
    ds = open_dataset(simulated("harbour", 0, 60.0))
    assert extractor_preset(ds) == extractor_config("default", noise=ds.config.noise)
    assert extractor_preset("marina").sector_deg == 360.0
    default = RunConfig.for_dataset(ds, "ekf")
    typed = replace(default, backend=replace(default.backend, min_rho_m=2.0))
    run = run_backend(ds, "ekf", config=typed)
    dotted = run_backend(ds, "ekf", {"ekf.min_rho_m": 2.0})
    assert run.metrics["settings"] == dotted.metrics["settings"] == {"ekf.min_rho_m": 2.0}
    for key in ("ate_mean_m", "landmarks", "line_features", "assoc_observations"):
        assert run.metrics[key] == dotted.metrics[key], key
    with pytest.raises(SettingError, match="either settings or config"):
        run_backend(ds, "ekf", {"ekf.min_rho_m": 2.0}, config=typed)
    with pytest.raises(SettingError, match="config.backend.*EkfConfig, got GraphConfig"):
        run_backend(ds, "ekf", config=replace(default, backend=GraphConfig()))


def test_a_typed_config_made_for_another_dataset_is_refused(
    simulated: Callable[..., Path], tmp_path: Path
) -> None:
    """A RunConfig made for dataset A and run on B, whose [noise] differs, took A's noise
    silently (it showed only as 'settings' B was never given); it is refused, naming both
    datasets and what differs, before any work. The same data in another folder, or the
    config untied (dataset=None), still runs."""
    import shutil

    from sonarslam.slam.run.run import _typed_settings

    a_root = simulated("harbour", 0, 60.0)
    b_root = shutil.copytree(a_root, tmp_path / "b")
    toml = b_root / "sonarslam.toml"
    toml.write_text(toml.read_text().replace("dvl_sigma_mps = 0.02", "dvl_sigma_mps = 0.1"))
    a, b = open_dataset(a_root), open_dataset(b_root)
    config = RunConfig.for_dataset(a, "ekf")
    untied = replace(config, dataset=None)
    assert untied == config  # which dataset made it is not a setting
    silent = _typed_settings(b, "ekf", untied, None)  # what run_backend ran with before
    assert silent == {"ekf.noise.dvl_sigma_mps": 0.02}
    message = (
        rf"config.dataset: the RunConfig was made for {a_root} .* run on {b_root}, whose"
        r" \[noise\] \(dvl_sigma_mps\) differ"
    )
    with pytest.raises(SettingError, match=message):
        run_backend(b, "ekf", config=config)
    same = shutil.copytree(a_root, tmp_path / "same")  # the same calibration elsewhere
    assert _typed_settings(open_dataset(same), "ekf", config, None) == {}
