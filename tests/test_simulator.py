"""The MSIS simulator: determinism, geometry of the beams, sensor logs against the truth."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pymap3d
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from sonarslam.datasets.config import load_dataset_config
from sonarslam.datasets.geodesy import ddmm_to_degrees, degrees_to_ddmm
from sonarslam.datasets.islog import read_is_log
from sonarslam.datasets.logfile import read_table
from sonarslam.datasets.records import Attitude, DvlVelocity, GpsFix
from sonarslam.datasets.simulator import (
    World,
    beam_axis_hits,
    cast_rays,
    free_path,
    harbour_world,
    make_scenario,
    pool_world,
    random_harbour_world,
    simulate,
    simulate_records,
    survey,
)
from sonarslam.datasets.simulator.msis import transducer_angles
from sonarslam.datasets.simulator.world import (
    HARBOUR_ROTATION_RAD,
    clearance_m,
    inside,
    rotate_points,
)
from sonarslam.datasets.simulator.writer import TRUTH_SCHEMA
from sonarslam.features.geometry import wrap_angle
from sonarslam.features.pose_source import PoseSource
from sonarslam.sonar.beam import Mounting, SonarBeam, SonarHead

FILE_SUFFIXES = ("_IS.log", "_IS_timestamps.log", "_SETUP.log", "_DVL.log", "_MTi.log", "_DGPS.log")


@pytest.fixture(scope="module")
def harbour_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A 300 s harbour run written to disk (seed 1)."""
    return simulate("harbour", 1, tmp_path_factory.mktemp("harbour"), duration_s=300.0)


@pytest.fixture(scope="module")
def harbour_sim():
    """The same run in memory."""
    return simulate_records(make_scenario("harbour", 1, 300.0))


def _files(directory: Path, prefix: str) -> list[Path]:
    return [directory / f"{prefix}{s}" for s in FILE_SUFFIXES] + [
        directory / "sonarslam.toml",
        directory / "truth.json",
    ]


# --- determinism -------------------------------------------------------------------------------


@pytest.mark.parametrize("kind", ["harbour", "random", "pool"])
def test_same_seed_same_bytes_other_seed_differs(kind: str, tmp_path: Path) -> None:
    a = simulate(kind, 3, tmp_path / "a", duration_s=20.0)
    b = simulate(kind, 3, tmp_path / "b", duration_s=20.0)
    c = simulate(kind, 4, tmp_path / "c", duration_s=20.0)
    for fa, fb in zip(_files(a, f"sim_{kind}_3"), _files(b, f"sim_{kind}_3"), strict=True):
        assert fa.read_bytes() == fb.read_bytes(), fa.name
    is_3 = (a / f"sim_{kind}_3_IS.log").read_text().splitlines()[7:]
    is_4 = (c / f"sim_{kind}_4_IS.log").read_text().splitlines()[7:]
    assert len(is_3) == len(is_4)
    # same times and angles would be a coincidence; the intensities must differ beam by beam
    assert sum(x.split()[3:] != y.split()[3:] for x, y in zip(is_3, is_4, strict=True)) > 0.9 * len(
        is_3
    )
    assert (a / "truth.json").read_bytes() != (c / "truth.json").read_bytes()


def test_random_world_depends_on_seed_only() -> None:
    w1 = random_harbour_world(np.random.default_rng(7))
    w2 = random_harbour_world(np.random.default_rng(7))
    w3 = random_harbour_world(np.random.default_rng(8))
    np.testing.assert_array_equal(w1.walls_m, w2.walls_m)
    assert w1.walls_m.shape != w3.walls_m.shape or not np.allclose(w1.walls_m, w3.walls_m)


# --- worlds and paths --------------------------------------------------------------------------


def _endpoint_degrees_even(world: World) -> bool:
    pts = np.round(world.walls_m.reshape(-1, 2), 6)
    _, counts = np.unique(pts, axis=0, return_counts=True)
    return bool(np.all(counts % 2 == 0))


def test_pool_matches_the_seed_paper() -> None:
    w = pool_world()
    lengths = np.linalg.norm(w.walls_m[:, 1] - w.walls_m[:, 0], axis=1)
    np.testing.assert_allclose(np.sort(lengths), [2.0, 2.0, 4.0, 4.0], atol=1e-12)
    assert inside(w, [[0.0, 0.0]])[0]
    centre = w.walls_m[:, 0].mean(axis=0)
    assert np.hypot(*centre) > 0.3  # sonar not at the centre
    d = w.walls_m[:, 1] - w.walls_m[:, 0]
    off_axis = np.abs(wrap_angle(4.0 * np.arctan2(d[:, 1], d[:, 0]))) / 4.0
    assert np.all(off_axis > np.deg2rad(10.0))  # no wall square to the world axes
    assert clearance_m(w, [[0.0, 0.0]])[0] == pytest.approx(0.8, abs=1e-9)


def test_harbour_has_basins_and_channel() -> None:
    w = harbour_world()
    assert _endpoint_degrees_even(w)
    # in the harbour's own frame: ~310 m x 100 m, a 20 m wide channel from x = 0 to 170 m
    own = rotate_points(w.walls_m.reshape(-1, 2), -HARBOUR_ROTATION_RAD)
    span = own.max(axis=0) - own.min(axis=0)
    np.testing.assert_allclose(span, [310.0, 100.0], atol=1e-9)
    channel = rotate_points(
        np.array([[20.0, 0.0], [85.0, 0.0], [150.0, 0.0]]), HARBOUR_ROTATION_RAD
    )
    assert np.all(inside(w, channel))
    np.testing.assert_allclose(clearance_m(w, channel), 10.0, atol=1e-9)
    outside = rotate_points(np.array([[85.0, 12.0], [85.0, -12.0]]), HARBOUR_ROTATION_RAD)
    assert not np.any(inside(w, outside))


@pytest.mark.parametrize("seed", range(5))
def test_random_harbour_is_closed_and_sized(seed: int) -> None:
    w = random_harbour_world(np.random.default_rng(seed))
    assert _endpoint_degrees_even(w)
    x0, y0, x1, y1 = w.bounds_m
    assert 30.0 <= max(x1 - x0, y1 - y0) <= 600.0
    d = w.walls_m[:, 1] - w.walls_m[:, 0]
    # rectilinear: all walls at one angle modulo 90 deg, and that angle is a random rotation
    quarter = wrap_angle(4.0 * np.arctan2(d[:, 1], d[:, 0])) / 4.0
    np.testing.assert_allclose(wrap_angle(4.0 * (quarter - quarter[0])), 0.0, atol=1e-9)
    assert abs(quarter[0]) > 1e-6


def _check_trajectory(world: World, tr, margin_m: float = 3.0) -> None:
    xy = tr.wTb[:, :2]
    assert np.all(inside(world, xy))
    assert clearance_m(world, xy).min() >= margin_m - 1e-9
    # truth is self-consistent: finite differences of the poses give the body velocity and yaw rate
    dt = np.diff(tr.t_s)
    v_w = np.diff(xy, axis=0) / dt[:, None]
    yaw_mid = tr.wTb[:-1, 2] + wrap_angle(np.diff(tr.wTb[:, 2])) / 2.0
    c, s = np.cos(yaw_mid), np.sin(yaw_mid)
    v_b = np.column_stack([c * v_w[:, 0] + s * v_w[:, 1], -s * v_w[:, 0] + c * v_w[:, 1]])
    v_mid = (tr.v_body_mps[1:] + tr.v_body_mps[:-1]) / 2.0
    np.testing.assert_allclose(v_b, v_mid, atol=2e-3)
    w_fd = wrap_angle(np.diff(tr.wTb[:, 2])) / dt
    w_mid = (tr.yaw_rate_rad_per_s[1:] + tr.yaw_rate_rad_per_s[:-1]) / 2.0
    # a fillet starts with a jump of curvature: allow it at the few samples that straddle one
    assert np.mean(np.abs(w_fd - w_mid) < 1e-3) > 0.99
    speed = np.hypot(*tr.v_body_mps.T)
    assert 0.2 <= speed.mean() <= 0.5


def test_harbour_survey_stays_clear_over_a_full_loop() -> None:
    w = harbour_world()
    tr = survey(w, 2400.0)
    _check_trajectory(w, tr)
    assert isinstance(tr, PoseSource) and tr.covariance(tr.t_s[0]) is None
    # the loop reaches the east basin (beyond the 170 m channel) and comes back
    own = rotate_points(tr.wTb[:, :2], -HARBOUR_ROTATION_RAD)
    assert own[:, 0].max() > 200.0 and own[:, 0].min() < -55.0


@pytest.mark.parametrize("seed", range(4))
def test_free_path_stays_clear(seed: int) -> None:
    rng = np.random.default_rng(seed)
    w = random_harbour_world(rng)
    _check_trajectory(w, free_path(w, rng, 600.0))


def test_transducer_angles_continuous_and_sector() -> None:
    step = math.radians(1.8)
    a = transducer_angles(450, step)
    assert a[0] == 0.0 and np.all((a >= 0.0) & (a < 2.0 * np.pi))
    np.testing.assert_allclose(wrap_angle(np.diff(a)), step, atol=2e-6)
    np.testing.assert_allclose(a[200], 0.0, atol=1e-6)
    s = transducer_angles(100, step, start_rad=1.0, sector_rad=math.radians(18.0))
    np.testing.assert_allclose(np.abs(np.diff(s)), step, atol=2e-6)
    assert s.min() == pytest.approx(1.0, abs=1e-6)
    assert s.max() == pytest.approx(1.0 + math.radians(18.0), abs=1e-6)


# --- beam geometry -----------------------------------------------------------------------------


def test_beam_axis_uses_angle_sense_and_mounting() -> None:
    # a 20 m x 20 m box centred on the body at the origin, body yaw 90 deg (facing North)
    box = np.array([[-10.0, -10.0], [10.0, -10.0], [10.0, 10.0], [-10.0, 10.0]])
    world = World("box", np.stack([box, np.roll(box, -1, axis=0)], axis=1))
    head = SonarHead(angle_sense=-1)
    bTs = Mounting(x_m=0.3, yaw_rad=math.pi)  # sonar 0.3 m ahead, looking backwards
    wTb = np.tile([0.0, 0.0, math.pi / 2.0], (3, 1))
    # sonar at (0, 0.3) facing South; a = 0 looks South; a = +90 deg turns clockwise: West
    r, inc = beam_axis_hits(world, head, bTs, wTb, [0.0, math.pi / 2.0, math.radians(30.0)])
    np.testing.assert_allclose(r[:2], [10.3, 10.0], atol=1e-9)
    np.testing.assert_allclose(inc[:2], [0.0, 0.0], atol=1e-9)
    # 30 deg clockwise of South: towards South-West, meets y = -10 at 10.3 / cos(30 deg)
    assert r[2] == pytest.approx(10.3 / math.cos(math.radians(30.0)), abs=1e-9)
    assert inc[2] == pytest.approx(math.radians(30.0), abs=1e-9)


@settings(max_examples=200, deadline=None)
@given(
    ox=st.floats(-50, 50), oy=st.floats(-50, 50), ang=st.floats(-np.pi, np.pi),
    r_true=st.floats(0.1, 100.0), rel=st.floats(0.2, np.pi - 0.2),
    before=st.floats(0.05, 20.0), after=st.floats(0.05, 20.0),
)  # fmt: skip
def test_cast_rays_finds_a_constructed_hit(ox, oy, ang, r_true, rel, before, after) -> None:
    o = np.array([ox, oy])
    d = np.array([np.cos(ang), np.sin(ang)])
    e = np.array([np.cos(ang + rel), np.sin(ang + rel)])  # wall direction, not parallel to the ray
    p = o + r_true * d
    wall = np.array([[p - before * e, p + after * e]])
    r, inc = cast_rays(wall, [o], [[ang]])
    assert r[0, 0] == pytest.approx(r_true, abs=1e-9 * (1.0 + r_true) / abs(np.sin(rel)))
    assert inc[0, 0] == pytest.approx(abs(np.pi / 2 - rel), abs=1e-6)
    # the same wall slid along itself past the hit point, or the ray turned round: no hit
    slid = wall + (before + 0.01) * e
    behind = np.array([[o - r_true * d - before * e, o - r_true * d + after * e]])
    r_miss, inc_miss = cast_rays(np.concatenate([slid, behind]), [o], [[ang]])
    assert np.isnan(r_miss[0, 0]) and np.isnan(inc_miss[0, 0])


@pytest.mark.parametrize(
    ("kind", "duration_s"), [("harbour", 300.0), ("random", 300.0), ("pool", 60.0)]
)
def test_argmax_bin_at_true_range_for_low_incidence(
    kind: str, duration_s: float, harbour_sim
) -> None:
    sim = harbour_sim if kind == "harbour" else simulate_records(make_scenario(kind, 1, duration_s))
    head = sim.scenario.head
    intens = np.stack([b.intensities for b in sim.beams])
    first = int(np.ceil(sim.scenario.echo.dead_zone_m / head.bin_size_m))
    argmax = np.argmax(intens[:, first:], axis=1) + first
    r = sim.beam_axis_range_m
    inc = sim.beam_axis_incidence_rad
    low = (
        np.isfinite(r)
        & (r > sim.scenario.echo.dead_zone_m + 5 * head.bin_size_m)
        & (r < head.range_max_m - 1.0)
        & (inc < np.deg2rad(15.0))
    )
    assert low.sum() >= 100
    err = argmax[low] - head.range_to_bin(r[low])
    assert np.mean(np.abs(err) <= 1) >= 0.90
    # beams that see no wall in range show no echo above the far background
    blind = ~np.isfinite(r) | (r > head.range_max_m + 1.0)
    if blind.sum() > 20:
        assert np.median(intens[blind, first:].max(axis=1)) < np.median(
            intens[low, first:].max(axis=1)
        )


def test_dead_zone_is_ringing_not_walls() -> None:
    sim = simulate_records(make_scenario("pool", 2, 30.0))
    head = sim.scenario.head
    intens = np.stack([b.intensities for b in sim.beams]).astype(float)
    n_dead = int(sim.scenario.echo.dead_zone_m / head.bin_size_m)
    # ringing: strong in the first bins, decaying to the background by the end of the dead zone
    assert intens[:, 0].mean() > 5.0 * intens[:, n_dead - 1].mean()
    assert intens[:, n_dead - 1].mean() < 20.0


# --- logs --------------------------------------------------------------------------------------


def test_logs_parse_with_the_marina_columns(harbour_dir: Path, harbour_sim) -> None:
    p = harbour_dir / "sim_harbour_1"
    expected = {"_DVL.log": 32, "_MTi.log": 10, "_DGPS.log": 10, "_IS_timestamps.log": 2,
                "_SETUP.log": 3}  # fmt: skip
    rows = {
        "_DVL.log": harbour_sim.dvl.t_s.size,
        "_MTi.log": harbour_sim.ahrs.t_s.size,
        "_DGPS.log": harbour_sim.gps.t_s.size,
        "_IS_timestamps.log": len(harbour_sim.beams),
        "_SETUP.log": 1,
    }
    for suffix, n_cols in expected.items():
        table = read_table(f"{p}{suffix}", n_columns=n_cols, time_column=None)
        assert table.skipped == 0
        assert table.data.shape == (rows[suffix], n_cols)
    setup = read_table(f"{p}_SETUP.log", time_column=None).data[0]
    np.testing.assert_allclose(setup, [50.0, 0.1, math.radians(1.8)], rtol=1e-12)
    stamps = read_table(f"{p}_IS_timestamps.log").data
    np.testing.assert_allclose(stamps[:, 0], [b.t for b in harbour_sim.beams], atol=5e-4)
    np.testing.assert_allclose(stamps[:, 1], np.round((stamps[:, 0] % 86400.0) * 1000.0), atol=0.5)
    cfg = load_dataset_config(harbour_dir / "sonarslam.toml")
    head = harbour_sim.scenario.head
    assert (cfg.sonar.n_bins, cfg.sonar.angle_sense) == (head.n_bins, head.angle_sense)
    np.testing.assert_allclose(
        [cfg.sonar.bin_size_m, cfg.sonar.step_rad, cfg.sonar.beam_width_rad],
        [head.bin_size_m, head.step_rad, head.beam_width_rad],
        rtol=1e-12,
    )
    assert cfg.sonar_mounting.x_m == 0.3
    assert math.degrees(cfg.sonar_mounting.yaw_rad) == pytest.approx(180.0, abs=1e-9)
    assert math.degrees(cfg.dvl_mounting.yaw_rad) == pytest.approx(-90.0, abs=1e-9)
    assert cfg.ahrs_mounting.yaw_rad == 0.0


def test_is_log_round_trip(harbour_dir: Path, harbour_sim) -> None:
    beams = read_is_log(harbour_dir / "sim_harbour_1_IS.log")
    assert len(beams) == len(harbour_sim.beams)
    np.testing.assert_array_equal(
        np.stack([b.intensities for b in beams]),
        np.stack([b.intensities for b in harbour_sim.beams]),
    )
    np.testing.assert_allclose(
        [b.transducer_angle_rad for b in beams],
        [b.transducer_angle_rad for b in harbour_sim.beams],
        atol=5e-7,
    )
    np.testing.assert_allclose([b.t for b in beams], [b.t for b in harbour_sim.beams], atol=5e-4)
    assert not any(b.thresholded for b in beams)


def test_dvl_log_matches_truth_within_noise(harbour_dir: Path, harbour_sim) -> None:
    d = read_table(harbour_dir / "sim_harbour_1_DVL.log", n_columns=32).data
    cfg = load_dataset_config(harbour_dir / "sonarslam.toml")
    sigma = harbour_sim.scenario.noise.dvl_sigma_mps
    valid = d[:, 14] == 1
    assert 0 < np.count_nonzero(~valid) < 0.3 * valid.size  # some bottom-lock dropouts
    for start, end in harbour_sim.dvl.dropouts_s:
        in_gap = (d[:, 0] >= start) & (d[:, 0] <= end)
        assert not np.any(valid & in_gap)
    t = d[valid, 0]
    v_dvl = d[valid][:, [11, 12]] / 100.0
    c, s = math.cos(cfg.dvl_mounting.yaw_rad), math.sin(cfg.dvl_mounting.yaw_rad)
    v_body = np.column_stack([c * v_dvl[:, 0] - s * v_dvl[:, 1], s * v_dvl[:, 0] + c * v_dvl[:, 1]])
    err = v_body - harbour_sim.trajectory.velocity_body_mps(t)
    n = err.shape[0]
    assert np.all(np.abs(err.mean(axis=0)) < 4.0 * sigma / math.sqrt(n))
    rms = np.sqrt(np.mean(err**2, axis=0))
    np.testing.assert_allclose(rms, sigma, rtol=0.2)
    # the body moves mostly forward, so the DVL (mounted at -90 deg) sees it on its +y axis
    assert np.mean(v_dvl[:, 1]) > 0.3
    # the DVL compass: heading of the DVL x axis, clockwise from North
    yaw_dvl = harbour_sim.trajectory.poses(t)[:, 2] + cfg.dvl_mounting.yaw_rad
    comp_err = wrap_angle(np.deg2rad(90.0 - d[valid, 22]) - yaw_dvl)
    sigma_c = math.radians(harbour_sim.scenario.noise.dvl_compass_sigma_deg)
    assert abs(comp_err.mean()) < 4.0 * sigma_c / math.sqrt(n)
    assert np.sqrt(np.mean(comp_err**2)) == pytest.approx(sigma_c, rel=0.2)


def test_mti_log_matches_truth_with_bias(harbour_dir: Path, harbour_sim) -> None:
    m = read_table(harbour_dir / "sim_harbour_1_MTi.log", n_columns=10).data
    noise = harbour_sim.scenario.noise
    t = m[:, 0]
    yaw_ahrs = np.deg2rad(90.0 - m[:, 3])  # readers' conversion, AHRS mounting yaw is 0
    err = np.rad2deg(wrap_angle(yaw_ahrs - harbour_sim.trajectory.poses(t)[:, 2]))
    assert err.mean() == pytest.approx(
        -noise.ahrs_bias_deg, abs=4.0 * noise.ahrs_sigma_deg / math.sqrt(t.size)
    )
    assert err.std() == pytest.approx(noise.ahrs_sigma_deg, rel=0.1)
    assert np.all(np.abs(m[:, 3]) <= 180.0)
    rate_err = -m[:, 6] - harbour_sim.trajectory.yaw_rate_at(t)
    assert np.sqrt(np.mean(rate_err**2)) == pytest.approx(noise.ahrs_rate_sigma_rad_per_s, rel=0.1)
    assert m[:, 9].mean() == pytest.approx(-9.81, abs=0.01)


def test_gps_first_fix_and_local_frame(harbour_dir: Path, harbour_sim) -> None:
    truth = json.loads((harbour_dir / "truth.json").read_text())
    g = read_table(harbour_dir / "sim_harbour_1_DGPS.log", n_columns=10).data
    o = truth["geodetic_origin"]
    lat, lon = ddmm_to_degrees(g[:, 1]), ddmm_to_degrees(g[:, 2])
    e, n, _ = pymap3d.geodetic2enu(lat, lon, 0.0, o["lat_deg"], o["lon_deg"], o["h_m"])
    enu = np.column_stack([e, n])
    np.testing.assert_allclose(enu[0], truth["first_fix_enu_m"], atol=1e-6)
    assert g[0, 0] == truth["first_fix_t"]
    sigma = truth["noise"]["gps_sigma_m"]
    true_xy = harbour_sim.trajectory.poses(g[:, 0])[:, :2]
    assert np.hypot(*(enu[0] - true_xy[0])) < 4.0 * sigma
    err = enu - true_xy
    assert np.all(np.abs(err.mean(axis=0)) < 4.0 * sigma / math.sqrt(err.shape[0]))
    np.testing.assert_allclose(np.sqrt(np.mean(err**2, axis=0)), sigma, rtol=0.15)
    # the readers' frame (origin at the first fix) is the world shifted by first_fix_enu_m
    e1, n1, _ = pymap3d.geodetic2enu(lat, lon, 0.0, lat[0], lon[0], 0.0)
    np.testing.assert_allclose(
        np.column_stack([e1, n1]), enu - np.array(truth["first_fix_enu_m"]), atol=0.02
    )
    # ddmm.mmmmmm: the marina's origin writes as 4212.225 / 306.2832
    np.testing.assert_allclose(
        degrees_to_ddmm(np.array([o["lat_deg"], o["lon_deg"]])), [4212.225, 306.2832], atol=1e-9
    )


def test_truth_json_schema(harbour_dir: Path, harbour_sim) -> None:
    truth = json.loads((harbour_dir / "truth.json").read_text())
    assert truth["schema"] == TRUTH_SCHEMA
    assert (truth["kind"], truth["seed"], truth["prefix"]) == ("harbour", 1, "sim_harbour_1")
    poses = np.array(truth["body_poses"]["rows"])
    assert truth["body_poses"]["columns"] == ["t", "x_m", "y_m", "yaw_rad"]
    assert truth["body_poses"]["rate_hz"] == 10.0
    assert poses.shape == (3001, 4)
    np.testing.assert_allclose(poses[:, 1:], harbour_sim.trajectory.poses(poses[:, 0]), atol=1e-9)
    np.testing.assert_array_equal(np.array(truth["walls_m"]), harbour_sim.world.walls_m)
    beams = np.array(truth["beams"]["rows"], dtype=float)  # null -> nan
    assert beams.shape == (len(harbour_sim.beams), 4)
    np.testing.assert_allclose(beams[:, 2], harbour_sim.beam_axis_range_m, equal_nan=True)
    assert truth["mountings"]["sonar"] == {"x_m": 0.3, "y_m": 0.0, "yaw_rad": math.pi,
                                           "source": "simulator truth"}  # fmt: skip
    assert truth["head"]["angle_sense"] == -1


def test_a_truth_on_another_clock_is_said_with_both_spans(
    harbour_dir: Path, tmp_path: Path
) -> None:
    """A truth.json whose times miss the logs' (a bag recorded with simulated time, another
    run's truth) failed the run with "no reference position inside the trajectory's time
    span", naming neither file nor spans."""
    import shutil

    from sonarslam.datasets.source import open_dataset
    from sonarslam.slam.eval.truth import truth_trajectory

    folder = tmp_path / "h"
    shutil.copytree(harbour_dir, folder)
    truth = json.loads((folder / "truth.json").read_text())
    truth["body_poses"]["rows"] = [[r[0] - 1e6, *r[1:]] for r in truth["body_poses"]["rows"]]
    (folder / "truth.json").write_text(json.dumps(truth))
    with pytest.raises(
        ValueError, match=r"truth.json's body poses \(.*\) do not meet the navigation's"
    ):
        truth_trajectory(open_dataset(folder))


def test_records_are_time_ordered_and_typed(harbour_sim) -> None:
    recs = harbour_sim.records()
    t = np.array([r.t for r in recs])
    assert np.all(np.diff(t) >= 0.0)
    kinds = {type(r) for r in recs}
    assert kinds == {SonarBeam, DvlVelocity, Attitude, GpsFix}
    fixes = [r for r in recs if isinstance(r, GpsFix)]
    assert (fixes[0].east_m, fixes[0].north_m) == (0.0, 0.0)
