"""Drawn worlds: a different, valid, closed harbour and route for every seed, with the pieces the
issue asks for, revisits along the same track and from the other side, and each wall's own echo."""

from __future__ import annotations

import json
from collections import Counter
from pathlib import Path

import numpy as np
import pytest

from sonarslam.datasets.simulator import (
    World,
    drawn_world,
    make_scenario,
    make_world,
    simulate,
    survey,
)
from sonarslam.datasets.simulator.layout import LAP_RANGE_M, ROUTE_CLEARANCE_M
from sonarslam.datasets.simulator.msis import render_intensities
from sonarslam.datasets.simulator.path import route_samples
from sonarslam.datasets.simulator.scenario import (
    AHRS_BIAS_SIGMA_DEG,
    DRIFT_DVL_SCALE_SIGMA,
    HELD_BACK_SEED_MIN,
    MARINA_HEAD,
)
from sonarslam.datasets.simulator.world import clearance_m, inside, loop_segments
from sonarslam.features.geometry import wrap_angle
from sonarslam.features.line import LineFeature
from sonarslam.slam.eval.truth import association_scores, wall_lines
from sonarslam.slam.io.trajectory import Trajectory
from sonarslam.sonar.beam import Mounting

# tuning seeds only: the held-back range is never looked at by the tests either
SEEDS = range(0, 30)


@pytest.fixture(scope="module")
def worlds() -> dict[int, World]:
    return {s: drawn_world(np.random.default_rng(s)) for s in SEEDS}


def test_seeds_used_here_are_not_held_back() -> None:
    assert max(SEEDS) < HELD_BACK_SEED_MIN == 10_000


def test_every_world_is_a_closed_harbour_the_route_stays_inside(worlds: dict[int, World]) -> None:
    for seed, w in worlds.items():
        # closed: every wall end is the start of exactly one wall and the end of exactly one
        starts = Counter(map(tuple, np.round(w.walls_m[:, 0], 9)))
        ends = Counter(map(tuple, np.round(w.walls_m[:, 1], 9)))
        assert starts == ends and max(starts.values()) == 1, seed
        assert np.linalg.norm(w.walls_m[:, 1] - w.walls_m[:, 0], axis=1).min() > 1e-3, seed
        assert w.route_m is not None
        points, lap_m = route_samples(w.route_m, w.route_turn_radius_m, 0.5)
        assert inside(w, points).all(), seed
        assert clearance_m(w, points).min() >= ROUTE_CLEARANCE_M - 1e-9, seed
        assert LAP_RANGE_M[0] <= lap_m <= LAP_RANGE_M[1], seed
        assert w.layout is not None and w.layout["lap_m"] == pytest.approx(lap_m, abs=0.06)
        # a point well outside the harbour is not water
        far = w.walls_m.reshape(-1, 2).max(axis=0) + 50.0
        assert not inside(w, far[None])[0]


def test_worlds_hold_what_a_marina_has(worlds: dict[int, World]) -> None:
    basins = Counter()
    for seed, w in worlds.items():
        lay = w.layout
        assert lay is not None
        basins[len(lay["basins"])] += 1
        assert 1 <= len(lay["basins"]) <= 3 and len(lay["channels"]) >= 1, seed
        for width, length, dead_end in lay["channels"]:
            assert 15.0 <= width <= 40.0 and 50.0 <= length <= 250.0, seed
            assert dead_end == (len(lay["basins"]) == 1), seed
        for key in ("breakwaters", "docks", "piers", "pontoons", "hulls", "coves"):
            assert lay[key] >= 1, (seed, key)
        assert lay["curved_walls"] > 0 and w.wall_curve is not None
        # quays of collinear pieces: fewer distinct lines than straight walls
        straight = w.walls_m[w.wall_curve < 0]
        lines, of_wall = wall_lines(straight, rho_tol_m=1e-6, theta_tol_rad=1e-8)
        assert len(lines) < len(straight), seed
        # islands: one closed loop per pontoon and hull, inside the water
        assert w.wall_material is not None
        assert {"quay", "breakwater", "hull", "pontoon", "pier"} <= set(w.wall_material), seed
    assert set(basins) == {1, 2, 3} and min(basins.values()) >= 4  # all three kinds, often


def test_a_breakwater_has_two_parallel_faces_a_few_metres_apart(worlds: dict[int, World]) -> None:
    for seed, w in worlds.items():
        assert w.wall_material is not None
        bw = w.walls_m[np.array(w.wall_material) == "breakwater"]
        d = bw[:, 1] - bw[:, 0]
        length = np.linalg.norm(d, axis=1)
        faces = bw[length >= 20.0]  # the two long faces of the first basin's breakwater
        assert len(faces) >= 2, seed
        a, b = faces[0], faces[1]
        u = (a[1] - a[0]) / np.linalg.norm(a[1] - a[0])
        v = (b[1] - b[0]) / np.linalg.norm(b[1] - b[0])
        assert abs(abs(float(u @ v)) - 1.0) < 1e-9, seed
        gap = abs(float(u[0] * (b[0] - a[0])[1] - u[1] * (b[0] - a[0])[0]))
        assert 4.0 - 1e-9 <= gap <= 7.0 + 1e-9, seed


def test_a_seed_gives_one_world_and_seeds_differ() -> None:
    """The issue's complaint: `simulate harbour --seed 0` and `--seed 1` had the same walls,
    route, true poses and AHRS bias. Drawn worlds differ in all of them."""
    a, b = make_world(make_scenario("drawn", 0)), make_world(make_scenario("drawn", 1))
    again = make_world(make_scenario("drawn", 0))
    assert np.array_equal(a.walls_m, again.walls_m) and np.array_equal(a.route_m, again.route_m)
    assert a.walls_m.shape != b.walls_m.shape or not np.allclose(a.walls_m, b.walls_m)
    ta, tb = survey(a, 600.0, rate_hz=1.0), survey(b, 600.0, rate_hz=1.0)
    assert np.abs(ta.wTb[:, :2] - tb.wTb[:, :2]).max() > 10.0
    biases = [make_scenario("drawn", s).noise.ahrs_bias_deg for s in range(40)]
    assert len(set(biases)) == 40
    assert np.std(biases) == pytest.approx(AHRS_BIAS_SIGMA_DEG, rel=0.35)
    # the estimators are told the specification, not the realisation
    sc = make_scenario("drawn", 3)
    cfg = sc.dataset_config()
    assert cfg.noise.ahrs_sigma_deg == pytest.approx(np.hypot(0.5, AHRS_BIAS_SIGMA_DEG), rel=1e-12)
    assert cfg.noise.dvl_scale_sigma == DRIFT_DVL_SCALE_SIGMA
    assert sc.errors is not None and sc.duration_s == 1800.0


def test_the_route_revisits_along_the_same_track_and_from_the_other_side(
    worlds: dict[int, World],
) -> None:
    for seed in list(SEEDS)[:20]:
        w = worlds[seed]
        tr = survey(w, 1800.0, rate_hz=1.0)
        xy, yaw, t = tr.wTb[:, :2], tr.wTb[:, 2], tr.t_s - tr.t_s[0]
        # along the same track: the start is passed again 5-30 min later
        d0 = np.linalg.norm(xy - xy[0], axis=1)
        again = t[(t > 120.0) & (d0 < 1.0)]
        assert again.size and 300.0 <= again[0] <= 1800.0, seed
        # from the other side: a place passed again, heading the other way, minutes later
        i = np.arange(0, t.size, 5)
        dist = np.linalg.norm(xy[i, None] - xy[None, i], axis=-1)
        dt = t[i][None, :] - t[i][:, None]
        opposite = np.abs(wrap_angle(yaw[i][None, :] - yaw[i][:, None])) > np.radians(150.0)
        assert np.any((dist < 15.0) & (dt > 300.0) & opposite), seed


def _room(gain: float, band_m: float) -> World:
    walls = loop_segments([[-20.0, -20.0], [20.0, -20.0], [20.0, 20.0], [-20.0, 20.0]])
    return World("room", walls, wall_gain=np.full(4, gain), wall_band_m=np.full(4, band_m))


def test_each_wall_has_its_own_echo_strength_and_band_thickness() -> None:
    """In a square room, a stronger wall returns more, a thicker band returns further behind
    its face; the face (the first return) stays where it is."""
    angles = np.linspace(0.0, 2 * np.pi, 400, endpoint=False)
    poses = np.zeros((angles.size, 3))
    mounting = Mounting()

    def beams(gain: float, band_m: float) -> np.ndarray:
        rng = np.random.default_rng(0)
        return render_intensities(_room(gain, band_m), MARINA_HEAD, mounting, poses, angles, rng)

    weak, strong, thick = beams(0.3, 0.15), beams(0.75, 0.15), beams(0.3, 1.5)
    r = (np.arange(MARINA_HEAD.n_bins) + 1) * MARINA_HEAD.bin_size_m
    head_on = np.abs(np.sin(2 * angles)) < 0.05  # beams square to the nearest wall, 20 m away
    wall = (r > 19.5) & (r < 20.5)
    peak_ratio = strong[head_on][:, wall].max(axis=1) / weak[head_on][:, wall].max(axis=1)
    assert np.median(peak_ratio) == pytest.approx(2.5, rel=0.15)  # the same speckle draws
    behind = (r > 20.6) & (r < 21.5)  # behind the face: the band
    assert thick[head_on][:, behind].mean() > 1.8 * weak[head_on][:, behind].mean()
    far = r > 5.0  # past the transducer's ringing
    face = r[far][np.argmax(thick[head_on][:, far] > 60, axis=1)]
    assert np.median(np.abs(face - 20.0)) <= 0.2  # (a false return may come first)


def test_truth_json_holds_the_walls_echo_and_the_layout(tmp_path: Path) -> None:
    out = simulate("drawn", seed=5, out_dir=tmp_path, duration_s=30.0)
    truth = json.loads((out / "truth.json").read_text())
    w = make_world(make_scenario("drawn", 5))
    assert truth["kind"] == "drawn" and truth["layout"] == json.loads(json.dumps(w.layout))
    assert len(truth["walls"]["echo_gain"]) == len(truth["walls_m"]) == w.walls_m.shape[0]
    assert truth["walls"]["material"] == list(w.wall_material or ())
    assert truth["noise"]["ahrs_bias_deg"] == make_scenario("drawn", 5).noise.ahrs_bias_deg
    # the other kinds' truth.json has none of it
    other = json.loads((simulate("harbour", 0, tmp_path / "h", 20.0) / "truth.json").read_text())
    assert "walls" not in other and "layout" not in other


def test_a_curve_is_one_truth_unit_for_the_association_scores() -> None:
    """Two observations of one curved stretch, each matching a different facet, paired with
    one landmark: right with the curve as one unit, half wrong if each facet were a line."""
    centre, radius = np.zeros(2), 10.0
    phi = np.radians([0.0, 12.0, 24.0])
    pts = centre + radius * np.column_stack([np.cos(phi), np.sin(phi)])
    walls = np.stack([pts[:-1], pts[1:]], axis=1)
    curve = np.zeros(2, dtype=np.int64)
    truth = Trajectory(np.array([0.0, 10.0]), np.zeros((2, 3)))
    feats = []
    for k in range(2):  # each facet's own line, seen from the origin
        mid = walls[k].mean(axis=0)
        theta = float(np.arctan2(mid[1], mid[0]))
        rho = float(np.cos(np.radians(6.0)) * radius)
        feats.append(
            LineFeature(
                t=float(k),
                wTr=np.zeros(3),
                rho_m=rho,
                theta_rad=theta,
                cov=np.eye(2) * 1e-4,
                votes=20,
                endpoints_r=np.zeros((2, 2)),
            )
        )
    with_unit = association_scores(feats, [7, 7], walls, truth, np.zeros(3), wall_curve=curve)
    per_facet = association_scores(feats, [7, 7], walls, truth, np.zeros(3))
    assert with_unit.precision == 1.0 and per_facet.precision == 0.5


def test_drawn_worlds_carry_the_marinas_calibration_errors_untold() -> None:
    """Issue 29's error budget: the sonar mounting is off ``sonarslam.toml``'s by up to
    0.2 m / 0.5 deg, the range scale by 1-4 %, and the heading has a 2 deg place field."""
    from sonarslam.datasets.simulator.scenario import (
        DRAWN_HEADING_FIELD_DEG,
        DRAWN_MOUNT_OFFSET_MAX,
        DRAWN_RANGE_SCALE_ERROR,
        SONAR_MOUNTING,
    )

    scales, offsets = [], []
    for seed in range(20):
        sc = make_scenario("drawn", seed)
        told = sc.dataset_config().sonar_mounting
        assert (told.x_m, told.y_m, told.yaw_rad) == (
            SONAR_MOUNTING.x_m,
            SONAR_MOUNTING.y_m,
            SONAR_MOUNTING.yaw_rad,
        )
        true = sc.sonar_mounting
        d = np.array(
            [true.x_m - told.x_m, true.y_m - told.y_m, np.rad2deg(true.yaw_rad - told.yaw_rad)]
        )
        assert np.all(np.abs(d) <= DRAWN_MOUNT_OFFSET_MAX)
        offsets.append(d)
        assert sc.errors is not None and sc.errors.ahrs_heading_field_deg == DRAWN_HEADING_FIELD_DEG
        scales.append(sc.errors.sonar_range_scale)
    err = np.abs(np.array(scales) - 1.0)
    assert np.all((err >= DRAWN_RANGE_SCALE_ERROR[0]) & (err <= DRAWN_RANGE_SCALE_ERROR[1]))
    assert min(scales) < 1.0 < max(scales)  # both signs
    assert np.all(np.std(offsets, axis=0) > 0.3 * np.array(DRAWN_MOUNT_OFFSET_MAX))
    # the drift world keeps its errors as they were
    drift = make_scenario("drift", 0)
    assert drift.errors is not None and drift.errors.sonar_range_scale == 1.0
    assert drift.sonar_mounting_told is None


def test_the_heading_field_has_its_rms_and_wavelength() -> None:
    from sonarslam.datasets.simulator.sensors import heading_field

    rng = np.random.default_rng(0)
    xy = rng.uniform(-2000, 2000, (20000, 2))
    rms = [
        np.sqrt(np.mean(heading_field(xy, 2.0, 80.0, np.random.default_rng(s)) ** 2))
        for s in range(20)
    ]
    assert np.mean(rms) == pytest.approx(2.0, rel=0.1)
    # smooth at a metre, decorrelated over a wavelength
    p = rng.uniform(-200, 200, (5000, 2))
    a = heading_field(p, 2.0, 80.0, np.random.default_rng(7))
    near = heading_field(p + [1.0, 0.0], 2.0, 80.0, np.random.default_rng(7))
    assert np.sqrt(np.mean((a - near) ** 2)) < 0.25


def test_the_sonar_logs_echoes_at_the_scaled_range() -> None:
    """An echo from a wall at range r peaks at ``range_scale * r`` in the bins."""
    sc = make_scenario("pool", 0)
    w = make_world(sc)
    rng = np.random.default_rng(0)
    wTb = np.tile([0.0, 0.0, 0.3], (36, 1))
    angles = np.linspace(0.0, 2 * np.pi, 36, endpoint=False)
    from sonarslam.datasets.simulator.msis import EchoModel, beam_axis_hits

    quiet = EchoModel(
        speckle=False, clutter_prob_per_bin=0.0, false_return_prob_per_beam=0.0, dead_zone_m=0.0
    )
    peaks = []
    for scale in (1.0, 1.04):
        img = render_intensities(
            w, sc.head, sc.sonar_mounting, wTb, angles, rng, quiet, range_scale=scale
        )
        peaks.append(np.argmax(img.astype(float), axis=1) * sc.head.bin_size_m)
    r, _ = beam_axis_hits(w, sc.head, sc.sonar_mounting, wTb, angles)
    ok = np.isfinite(r) & (r > 1.0) & (r < 0.9 * sc.head.range_max_m / 1.04)
    assert ok.sum() > 20
    assert np.median(peaks[1][ok] - 1.04 * peaks[0][ok]) == pytest.approx(
        0.0, abs=2 * sc.head.bin_size_m
    )


def test_walls_a_gate_cannot_tell_apart_are_one_truth_unit() -> None:
    """Two quays on one line 40 m apart whose lines differ by 4 cm (drawn 5's walls 21 and 25,
    docs/research/consistency.md) are one truth unit, as exactly collinear ones are: an observation of
    either paired with the other's landmark is right. A parallel wall 0.58 m behind (drawn 7's
    walls 100 and 104), one 2 deg off, and the same walls under the exact tolerances of before
    stay apart."""
    from sonarslam.slam.eval.truth import SAME_LINE_RHO_M, truth_units

    walls = np.array(
        [
            [[0.0, 0.0], [30.0, 0.0]],  # quay A, y = 0
            [[70.0, 0.04], [100.0, 0.04]],  # quay B, 4 cm off A's line
            [[36.0, 0.58], [60.0, 0.58]],  # a step 0.58 m behind
            [[0.0, 5.0], [30.0, 5.0 + 30.0 * np.tan(np.radians(2.0))]],  # 2 deg off y = 5
            [[0.0, 5.0], [-30.0, 5.0]],  # y = 5, collinear with the start of the last
        ]
    )
    lines, unit, line_of_wall = truth_units(walls)
    u = unit[line_of_wall]
    assert u[0] == u[1], (lines, unit)
    assert len({u[0], u[2], u[3]}) == 3 and u[3] != u[4]
    assert SAME_LINE_RHO_M <= 0.1  # one range bin: the step is well beyond it
    exact = truth_units(walls, same_line_rho_m=1e-3, same_line_theta_rad=1e-4)
    assert exact[1][exact[2]][0] != exact[1][exact[2]][1]
    # a curve's facets stay one unit
    curve = np.array([-1, -1, -1, 0, 0])
    _, unit_c, low = truth_units(walls, wall_curve=curve)
    assert unit_c[low][3] == unit_c[low][4] and unit_c[low][0] == unit_c[low][1]
