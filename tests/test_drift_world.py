"""The drift world: systematic sensor errors in the logs as specified, and its geometry (walls
revisited, a breakwater with two faces, collinear quays, short piers, a moored hull)."""

from __future__ import annotations

import json
import math
from dataclasses import asdict, replace
from pathlib import Path

import numpy as np
import pytest

from sonarslam.datasets.config import load_dataset_config
from sonarslam.datasets.islog import read_is_log
from sonarslam.datasets.logfile import read_table
from sonarslam.datasets.simulator import (
    DriftErrors,
    EchoModel,
    Simulation,
    World,
    cast_rays,
    drift_world,
    make_scenario,
    simulate_records,
    survey,
    write_dataset,
)
from sonarslam.datasets.simulator.msis import render_intensities
from sonarslam.datasets.simulator.path import TrueMotion
from sonarslam.datasets.simulator.scenario import (
    DRIFT_DVL_SCALE_SIGMA,
    DRIFT_ECHO_RANGE_OFFSET_M,
    DRIFT_HEADING_WALK_DEG_PER_SQRT_S,
    _seed_streams,
)
from sonarslam.datasets.simulator.sensors import simulate_dvl
from sonarslam.datasets.simulator.world import (
    DRIFT_ROTATION_RAD,
    clearance_m,
    inside,
    rotate_points,
)
from sonarslam.features.geometry import wrap_angle
from sonarslam.slam.eval.truth import wall_lines_world
from sonarslam.sonar.beam import Mounting, SonarHead

SEED = 4


@pytest.fixture(scope="module")
def quiet(tmp_path_factory: pytest.TempPathFactory) -> tuple[Simulation, Path]:
    """A full 1,800 s drift run without the DVL's and the AHRS heading's white noise nor DVL
    dropouts (so that the systematic errors show exactly), and few sonar beams (fast)."""
    sc = make_scenario("drift", SEED)
    noise = replace(sc.noise, dvl_sigma_mps=0.0, dvl_dropout_rate_per_s=0.0, ahrs_sigma_deg=0.0)
    sim = simulate_records(replace(sc, noise=noise, beam_rate_hz=0.5))
    return sim, write_dataset(sim, tmp_path_factory.mktemp("drift_quiet"))


@pytest.fixture(scope="module")
def noisy(tmp_path_factory: pytest.TempPathFactory) -> tuple[Simulation, Path]:
    """300 s of the default drift scenario (all its noise), written to disk."""
    sim = simulate_records(make_scenario("drift", 1, 300.0))
    return sim, write_dataset(sim, tmp_path_factory.mktemp("drift_noisy"))


# --- the scenario --------------------------------------------------------------------------------


def test_drift_errors_are_drawn_per_seed_and_the_other_kinds_have_none() -> None:
    errors = [make_scenario("drift", s).errors for s in range(20)]
    assert all(e is not None for e in errors)
    k = np.array([e.dvl_scale_factor for e in errors if e is not None])
    b = np.array([e.dvl_bias_mps for e in errors if e is not None])
    assert np.all((np.abs(k) >= 0.01) & (np.abs(k) <= 0.02))
    assert (k > 0).any() and (k < 0).any()
    assert np.all(np.abs(b) <= 0.005) and np.unique(b[:, 0]).size == 20
    for e in errors:
        assert e is not None
        assert e.ahrs_heading_walk_deg_per_sqrt_s == DRIFT_HEADING_WALK_DEG_PER_SQRT_S
        assert e.echo_range_offset_m == DRIFT_ECHO_RANGE_OFFSET_M == 0.25
    assert make_scenario("drift", 3).errors == make_scenario("drift", 3).errors
    assert make_scenario("drift", 3).duration_s >= 1800.0
    for kind in ("pool", "harbour", "random"):
        assert make_scenario(kind, 3).errors is None
    with pytest.raises(ValueError, match="dvl_scale_factor"):
        DriftErrors(dvl_scale_factor=0.7)


def test_new_streams_leave_the_older_ones_as_they_were() -> None:
    """The drift errors and the heading walk have streams of their own, spawned after the six
    older ones: the pool, harbour and random runs draw exactly what they drew before."""
    for kind_index, kind in enumerate(("pool", "harbour", "random")):
        old = np.random.SeedSequence([7, kind_index]).spawn(6)
        streams = _seed_streams(7, kind)
        for name, seq in zip(("world", "path", "sonar", "dvl", "ahrs", "gps"), old, strict=True):
            np.testing.assert_array_equal(
                streams[name].random(4), np.random.default_rng(seq).random(4)
            )


# --- the errors in the logs ----------------------------------------------------------------------


def _dvl_truth_mps(trajectory: TrueMotion, m: Mounting, t: np.ndarray) -> np.ndarray:
    """True velocity of a DVL mounted at the body origin, in its own frame (m/s)."""
    assert m.x_m == 0.0 and m.y_m == 0.0
    v = trajectory.velocity_body_mps(t)
    c, s = math.cos(m.yaw_rad), math.sin(m.yaw_rad)
    return np.column_stack([c * v[:, 0] + s * v[:, 1], -s * v[:, 0] + c * v[:, 1]])


def test_dvl_log_is_the_scaled_and_biased_truth(quiet) -> None:
    """Without white noise the logged velocity is ``(1 + k) v + b`` to the log's 0.01 cm/s."""
    sim, folder = quiet
    truth = json.loads((folder / "truth.json").read_text())
    k = truth["errors"]["dvl_scale_factor"]
    b = np.array(truth["errors"]["dvl_bias_mps"])
    d = read_table(folder / f"sim_drift_{SEED}_DVL.log", n_columns=32).data
    assert np.all(d[:, 14] == 1)
    logged = d[:, [11, 12]] / 100.0
    v = _dvl_truth_mps(sim.trajectory, sim.scenario.dvl_mounting, d[:, 0])
    np.testing.assert_allclose(logged, (1.0 + k) * v + b, rtol=0.0, atol=6e-5)
    assert np.abs(logged - v).max() > 0.002  # the errors are there, far above the rounding


def test_dvl_with_white_noise_is_the_scaled_and_biased_truth_plus_that_noise() -> None:
    """With the DVL's white noise (0.02 m/s), the measurement minus ``(1 + k) v + b`` has zero
    mean (within four standard errors) and the noise's sigma (within 5 %), while the measurement
    minus ``v`` alone is biased far beyond its standard error."""
    sc = make_scenario("drift", SEED)
    assert sc.errors is not None
    tr = survey(drift_world(), sc.duration_s)
    noise = replace(sc.noise, dvl_dropout_rate_per_s=0.0)
    dvl = simulate_dvl(tr, sc.dvl_mounting, noise, np.random.default_rng(0), errors=sc.errors)
    v = _dvl_truth_mps(tr, sc.dvl_mounting, dvl.t_s)
    k, b = sc.errors.dvl_scale_factor, np.array(sc.errors.dvl_bias_mps)
    e = dvl.v_dvl_mps[:, :2] - ((1.0 + k) * v + b)
    se = noise.dvl_sigma_mps / math.sqrt(e.shape[0])
    assert np.all(np.abs(e.mean(axis=0)) < 4.0 * se)
    np.testing.assert_allclose(np.sqrt(np.mean(e**2, axis=0)), noise.dvl_sigma_mps, rtol=0.05)
    assert np.abs((dvl.v_dvl_mps[:, :2] - v).mean(axis=0)).max() > 6.0 * se


def test_heading_random_walk_is_in_the_mti_log(quiet) -> None:
    """Without white noise the logged heading's error is the constant bias plus a random walk
    whose increments over the 0.1 s between samples have the stated sigma (within 3 %, the
    increments of 18,000 samples) and are uncorrelated; ``truth.json`` holds the walk."""
    sim, folder = quiet
    truth = json.loads((folder / "truth.json").read_text())
    sigma = truth["errors"]["ahrs_heading_walk_deg_per_sqrt_s"]
    m = read_table(folder / f"sim_drift_{SEED}_MTi.log", n_columns=10).data
    t = m[:, 0]
    true_cw = 90.0 - np.rad2deg(sim.trajectory.poses(t)[:, 2])  # AHRS mounting yaw is 0
    err = np.rad2deg(wrap_angle(np.deg2rad(m[:, 3] - true_cw)))
    bias = sim.scenario.noise.ahrs_bias_deg
    assert err[0] == pytest.approx(bias, abs=2e-4)  # the walk starts at zero
    steps = np.diff(err) / np.sqrt(np.diff(t))
    assert steps.size > 17_000
    assert np.std(steps) == pytest.approx(sigma, rel=0.03)
    assert abs(np.mean(steps)) < 4.0 * sigma / math.sqrt(steps.size)
    assert abs(np.corrcoef(steps[:-1], steps[1:])[0, 1]) < 0.05
    walk = np.array(truth["ahrs_heading_walk"]["rows"])
    assert truth["ahrs_heading_walk"]["rate_hz"] == pytest.approx(1.0)
    at = np.searchsorted(t, walk[:, 0])
    np.testing.assert_allclose(t[at], walk[:, 0], atol=1e-9)
    np.testing.assert_allclose(err[at] - bias, walk[:, 1], atol=2e-4)
    assert np.abs(walk[:, 1]).max() > 3.0 * sigma  # it wanders


def test_truth_json_records_the_errors_and_the_estimators_are_told_only_the_specifications(
    noisy,
) -> None:
    sim, folder = noisy
    truth = json.loads((folder / "truth.json").read_text())
    assert sim.scenario.errors is not None
    assert truth["errors"] == json.loads(json.dumps(asdict(sim.scenario.errors)))
    assert (truth["kind"], truth["prefix"]) == ("drift", "sim_drift_1")
    # sonarslam.toml holds what the harbour's holds plus the sensors' specifications: the rate of
    # the heading walk and the size of the DVL's scale error, not their realisations, not the
    # DVL's bias nor the echo's offset
    written = load_dataset_config(folder / "sonarslam.toml")
    assert written.noise == replace(
        make_scenario("harbour", 1).dataset_config().noise,
        ahrs_bias_walk_deg_per_sqrt_s=DRIFT_HEADING_WALK_DEG_PER_SQRT_S,
        dvl_scale_sigma=DRIFT_DVL_SCALE_SIGMA,
    )
    assert written.sonar.range_offset_m == 0.0
    assert written.ahrs_deviation_rad == (0.0, 0.0) and written.sonar_time_offset_s == 0.0


def _ideal_echo(range_offset_m: float, wall_range_m: float) -> tuple[np.ndarray, np.ndarray]:
    """A noise-free beam on 5 mm bins straight at a wall ``wall_range_m`` ahead: bin ranges and
    intensities."""
    head = SonarHead(n_bins=1400, bin_size_m=0.005, angle_sense=1)
    walls = np.array([[[wall_range_m, -30.0], [wall_range_m, 30.0]]])
    echo = EchoModel(
        echo_gain=200.0,
        speckle=False,
        background_near=0.0,
        background_far=0.0,
        clutter_prob_per_bin=0.0,
        false_return_prob_per_beam=0.0,
    )
    intens = render_intensities(
        World("wall", walls),
        head,
        Mounting(),
        np.zeros((1, 3)),
        np.zeros(1),
        np.random.default_rng(0),
        echo,
        range_offset_m,
    )[0].astype(float)
    return head.bin_ranges_m(), intens


@pytest.mark.parametrize("wall_range_m", [4.0, 4.5037, 5.0021, 6.3333])
def test_echo_peaks_behind_the_wall_face_and_rises_on_it(wall_range_m: float) -> None:
    """The echo profile peaks ``range_offset_m`` behind the wall face and its leading edge (the
    first bin at half the peak) is on the face; without an offset both are on the face."""
    r, intens = _ideal_echo(0.25, wall_range_m)
    far = r > 2.0  # beyond the dead zone's ringing
    r, intens = r[far], intens[far]
    assert 200.0 < intens.max() < 255.0  # not clipped
    peak_m = r[np.argmax(intens)]
    edge_m = r[np.argmax(intens >= intens.max() / 2.0)]
    # the flat top of the rise (13 mm within one count of the peak) and the 5 mm bins
    assert peak_m - wall_range_m == pytest.approx(0.25, abs=0.02)
    assert edge_m - wall_range_m == pytest.approx(0.0, abs=0.01)
    r0, intens0 = _ideal_echo(0.0, wall_range_m)
    assert r0[far][np.argmax(intens0[far])] - wall_range_m == pytest.approx(0.0, abs=0.01)


def test_echo_in_the_sonar_log_peaks_behind_the_walls(noisy) -> None:
    """In the written IS log, the mean echo of the beams square to a wall (axis within 5 deg of
    the normal), against the bin's distance behind the true wall, peaks 0.25 m behind it and
    rises through half its peak on the face, within one 0.1 m bin: the counts clipped at 255 and
    the 3 deg beam meeting the wall a little obliquely pull both a few cm forward (the ideal
    echo is checked to the mm above)."""
    sim, folder = noisy
    beams = read_is_log(folder / "sim_drift_1_IS.log")
    intens = np.stack([b.intensities for b in beams]).astype(float)
    r, inc = sim.beam_axis_range_m, sim.beam_axis_incidence_rad
    square = np.isfinite(r) & (r > 3.0) & (r < 40.0) & (inc < np.deg2rad(5.0))
    assert square.sum() >= 200
    behind = sim.scenario.head.bin_ranges_m()[None, :] - r[square][:, None]
    near = np.abs(behind) <= 1.0
    cell = np.round(behind[near] / 0.02).astype(int) + 50  # 2 cm cells from -1 to 1 m
    mean = np.bincount(cell, weights=intens[square][near], minlength=101) / np.maximum(
        np.bincount(cell, minlength=101), 1
    )
    mean -= mean[:15].mean()  # the background in front of the wall
    cells_m = (np.arange(101) - 50) * 0.02
    assert cells_m[np.argmax(mean)] == pytest.approx(0.25, abs=0.1)
    assert -0.1 <= cells_m[np.argmax(mean >= mean.max() / 2.0)] <= 0.05


# --- the world ------------------------------------------------------------------------------------


def _own(world: World) -> np.ndarray:
    return rotate_points(world.walls_m, -DRIFT_ROTATION_RAD)


def test_drift_world_has_a_breakwater_collinear_quays_piers_and_a_hull() -> None:
    w = drift_world()
    walls = _own(w)
    length = np.linalg.norm(walls[:, 1] - walls[:, 0], axis=1)
    lines = wall_lines_world(walls)
    # the breakwater: one pair of parallel walls >= 50 m, 5 m apart, with water on both outsides
    pairs = []
    for i in range(len(walls)):
        for j in range(i + 1, len(walls)):
            parallel = abs(np.sin(lines[i, 1] - lines[j, 1])) < 1e-9
            if parallel and min(length[i], length[j]) >= 50.0:
                gap = abs(
                    np.dot(walls[j, 0] - walls[i, 0], [np.cos(lines[i, 1]), np.sin(lines[i, 1])])
                )
                if gap < 10.0:
                    pairs.append((i, j, gap))
    assert len(pairs) == 1 and pairs[0][2] == pytest.approx(5.0, abs=1e-9)
    i, j, _ = pairs[0]
    mid = (walls[i].mean(axis=0) + walls[j].mean(axis=0)) / 2.0
    normal = walls[i].mean(axis=0) - mid
    normal /= np.linalg.norm(normal)
    probes = np.array([mid, mid + 5.0 * normal, mid - 5.0 * normal])
    in_water = inside(w, rotate_points(probes, DRIFT_ROTATION_RAD))
    assert list(in_water) == [False, True, True]  # solid between the faces, water outside both
    # collinear quays with gaps: a line holding three pieces with two gaps of 10 m
    direction = walls[:, 1] - walls[:, 0]
    found = False
    for line in np.unique(np.round(lines, 6), axis=0):
        on = np.flatnonzero(np.all(np.abs(np.round(lines, 6) - line) < 1e-6, axis=1))
        if on.size >= 3 and np.all(length[on] >= 25.0):
            u = direction[on[0]] / length[on[0]]
            spans = np.sort(walls[on] @ u, axis=1)
            spans = spans[np.argsort(spans[:, 0])]
            gaps = spans[1:, 0] - spans[:-1, 1]
            found |= bool(np.all(gaps >= 9.9))
    assert found
    # three finger piers: 2 m tips with 6 m sides, water beyond each tip and solid behind it
    tips = np.flatnonzero(np.abs(length - 2.0) < 1e-9)
    assert tips.size == 3
    for k in tips:
        centre = walls[k].mean(axis=0)
        probes = np.array([centre + [1.0, 0.0], centre - [1.0, 0.0]])
        assert list(inside(w, rotate_points(probes, DRIFT_ROTATION_RAD))) == [True, False]
        assert sorted(length[[k - 1, k + 1]]) == pytest.approx([6.0, 6.0])
    # a moored hull: a closed 20 m x 5 m loop in the water, 3 m off the south quay
    hull = walls[-4:]
    assert sorted(np.linalg.norm(hull[:, 1] - hull[:, 0], axis=1)) == pytest.approx(
        [5.0, 5.0, 20.0, 20.0]
    )
    assert hull[:, :, 1].min() == pytest.approx(3.0)


def _seen(world: World, xy: np.ndarray, wall: int, max_range_m: float = 48.0) -> np.ndarray:
    """Whether some point of the wall's middle 80 % is within the sonar's range of each position,
    with nothing in between and at an incidence under 60 deg."""
    a, b = world.walls_m[wall]
    seen = np.zeros(xy.shape[0], dtype=bool)
    for u in np.linspace(0.1, 0.9, 9):
        d = a + u * (b - a) - xy
        r = np.hypot(d[:, 0], d[:, 1])
        hit_r, hit_inc = cast_rays(world.walls_m, xy, np.arctan2(d[:, 1], d[:, 0])[:, None])
        first = np.abs(hit_r[:, 0] - r) < 1e-6  # this point is the first wall on the ray
        seen |= first & (r < max_range_m) & (hit_inc[:, 0] < np.deg2rad(60.0))
    return seen


def test_drift_survey_is_clear_and_revisits_every_wall_minutes_later() -> None:
    w = drift_world()
    tr = survey(w, make_scenario("drift", 0).duration_s, rate_hz=1.0)
    xy = tr.wTb[:, :2]
    assert np.all(inside(w, xy)) and clearance_m(w, xy).min() >= 7.0 - 1e-9
    # the start is passed again after one lap, 15-16 min in
    back = np.hypot(*(xy - xy[0]).T)
    assert back[600:].min() < 1.0 and 900 <= 600 + int(np.argmin(back[600:])) <= 1000
    length = np.linalg.norm(w.walls_m[:, 1] - w.walls_m[:, 0], axis=1)
    hidden = len(w.walls_m) - 4  # the hull's side toward the quay, 3 m from it
    for k in np.flatnonzero(length >= 15.0):
        t_seen = np.flatnonzero(_seen(w, xy, int(k)))
        if k == hidden:
            assert t_seen.size == 0
            continue
        gaps = np.diff(t_seen)
        # seen, out of sight for at least 5 min, seen again
        assert t_seen.size > 60 and gaps.max() >= 300, (k, t_seen.size, gaps.max())
