"""slam.eval.leading_edges, walls, line_quality, line_stats: wall references fitted through leading
edges, and line statistics against them, checked where the answer is known (a simulated harbour,
lines drawn from known walls and covariances); the marina references when the data are there."""

from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pytest

from sonarslam.datasets.errors import DataError
from sonarslam.datasets.simulator import make_scenario, simulate_records
from sonarslam.datasets.simulator.world import inside
from sonarslam.features.geometry import (
    compose,
    inverse,
    line_world_to_frame,
    normalize_line,
    transform_points,
    wrap_angle,
)
from sonarslam.features.line import LineFeature, check_mounting
from sonarslam.slam.eval.consistency import chi2_gate
from sonarslam.slam.eval.leading_edges import (
    EdgeConfig,
    Edges,
    leading_edge_beams,
    leading_edge_points,
)
from sonarslam.slam.eval.line_quality import (
    AssociationGates,
    ScanReference,
    associate,
    evaluate_lines,
    quality_report,
    reproject,
    scan_lines,
    walls_from_segments,
)
from sonarslam.slam.eval.line_stats import error_stats
from sonarslam.slam.eval.truth import wall_lines_world
from sonarslam.slam.eval.walls import WallReference, fit_walls, wall_references, water_side
from sonarslam.slam.io.lines import read_lines_jsonl
from sonarslam.slam.io.trajectory import Trajectory
from sonarslam.slam.run.sources import gps_ahrs_trajectory
from sonarslam.sonar.beam import SonarBeam, SonarHead

T0_S = 1.7e9
#: A basin of 60 m x 30 m, water inside: four walls whose water side is the centre's.
BASIN = np.array(
    [
        [[0.0, 0.0], [60.0, 0.0]],
        [[60.0, 0.0], [60.0, 30.0]],
        [[60.0, 30.0], [0.0, 30.0]],
        [[0.0, 30.0], [0.0, 0.0]],
    ]
)
CENTRE = np.array([30.0, 15.0])


def cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """z of the cross product of planar vectors (..., 2)."""
    return a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]


def basin_walls() -> list[WallReference]:
    sides = [int(water_side(line, CENTRE)) for line in wall_lines_world(BASIN)]
    return walls_from_segments(BASIN, sides)


def drawn_line(
    rng: np.random.Generator,
    wall: WallReference,
    wTr: np.ndarray,
    cov: np.ndarray,
    bias_m: float,
    t: float,
) -> LineFeature:
    """A line of ``wall`` seen from ``wTr``: the truth in R plus ``(bias_m, 0)`` plus a draw of
    ``cov``; its segment is the wall's middle half moved onto the measured line."""
    z_true = line_world_to_frame(wall.line_w, wTr)[0]
    rho, theta = z_true + np.array([bias_m, 0.0]) + rng.multivariate_normal(np.zeros(2), cov)
    n = np.array([np.cos(theta), np.sin(theta)])
    q = transform_points(
        inverse(wTr),
        wall.endpoints_w[0] + np.outer([0.25, 0.75], wall.endpoints_w[1] - wall.endpoints_w[0]),
    )
    q = q - np.outer(q @ n - rho, n)  # onto the measured line
    r, th = normalize_line(rho, theta)
    return LineFeature(t, wTr, float(r), float(th), cov, 20, q, 20)


def basin_pose(rng: np.random.Generator, wall: WallReference) -> np.ndarray:
    """A sonar pose 5-20 m in front of a random point of the wall's middle, any yaw."""
    e = wall.endpoints_w
    foot = e[0] + rng.uniform(0.3, 0.7) * (e[1] - e[0])
    normal = wall.side * np.array([np.cos(wall.line_w[1]), np.sin(wall.line_w[1])])
    p = foot + rng.uniform(5.0, 12.0) * normal
    return np.array([p[0], p[1], rng.uniform(-np.pi, np.pi)])


def drawn_lines(
    seed: int, n: int, bias_by_wall_m: tuple[float, ...], cov: np.ndarray
) -> tuple[list[LineFeature], np.ndarray, list[WallReference]]:
    rng = np.random.default_rng(seed)
    walls = basin_walls()
    which = rng.integers(0, len(walls), n)
    lines = [
        drawn_line(rng, walls[k], basin_pose(rng, walls[k]), cov, bias_by_wall_m[k], T0_S + i)
        for i, k in enumerate(which)
    ]
    return lines, which, walls


# -- leading edges ----------------------------------------------------------------------------


def test_leading_edges_are_the_nearest_bin_of_each_run():
    head = SonarHead(n_bins=60, bin_size_m=0.1)
    mask = np.zeros(60, dtype=np.uint8)
    mask[[5, 12, 13, 14, 16, 17, 30, 31, 45]] = 255  # runs (gaps < 1 m): 5-17, 30-31, 45
    raw = np.zeros(60, dtype=np.uint8)
    raw[[12, 13, 14]] = [70, 200, 90]
    raw[40] = 59  # below the threshold
    raw[50] = 61
    beams = [SonarBeam(T0_S, 0.0, mask, thresholded=True), SonarBeam(T0_S + 1, 0.0, raw)]
    out = leading_edge_beams(
        beams, head, EdgeConfig(run_gap_m=1.0, min_range_m=0.0, intensity_threshold=60.0)
    )
    assert np.flatnonzero(out[0].intensities).tolist() == [5, 30, 45]
    assert np.flatnonzero(out[1].intensities).tolist() == [12, 50]
    assert all(b.thresholded for b in out)
    # a gap of 1.3 m cuts a run: bins 5 and 19 are both leading edges
    mask2 = np.zeros(60, dtype=np.uint8)
    mask2[[5, 19]] = 255
    (edge,) = leading_edge_beams(
        [SonarBeam(T0_S, 0.0, mask2, thresholded=True)], head, EdgeConfig(min_range_m=0.0)
    )
    assert np.flatnonzero(edge.intensities).tolist() == [5, 19]


# -- wall references --------------------------------------------------------------------------


@pytest.fixture(scope="module")
def harbour():
    """A simulated harbour, 600 s (seed 3), its leading edges placed by the true poses."""
    scenario = make_scenario("harbour", 3, duration_s=600.0)
    sim = simulate_records(scenario)
    edges = leading_edge_points(
        sim.beams, scenario.head, scenario.sonar_mounting, sim.trajectory, EdgeConfig()
    )
    return sim, edges, fit_walls(edges)


def test_references_of_a_simulated_harbour_lie_on_its_walls(harbour):
    """Every reference lies on a true wall (ends within 0.3 m of its line, within 0.5 deg of its
    direction, with the water on the right side); every wall with 150 edges on it has a
    reference covering 70 % of the part seen; no two references of one wall overlap."""
    sim, edges, walls = harbour
    true = sim.world.walls_m
    lines = wall_lines_world(true)
    assert len(walls) >= 5
    of_wall: dict[int, list[WallReference]] = {}
    for w in walls:
        dist = [
            np.abs(w.endpoints_w @ [np.cos(ln[1]), np.sin(ln[1])] - ln[0]).max() for ln in lines
        ]
        k = int(np.argmin(dist))
        ln, seg = lines[k], true[k]
        assert dist[k] <= 0.3, (w.index, k, dist[k])
        assert abs(float(wrap_angle(2.0 * (w.line_w[1] - ln[1])))) / 2.0 <= np.deg2rad(0.5)
        n = np.array([np.cos(ln[1]), np.sin(ln[1])])
        water = bool(inside(sim.world, (seg.mean(axis=0) + 1.0 * n)[None])[0])
        assert int(water_side(w.line_w, seg.mean(axis=0) + 1.0 * n)) == (
            w.side if water else -w.side
        )
        assert w.sigma_m < 0.3
        of_wall.setdefault(k, []).append(w)
    for k, (ln, seg) in enumerate(zip(lines, true, strict=True)):
        n = np.array([np.cos(ln[1]), np.sin(ln[1])])
        u = np.array([-n[1], n[0]])
        s0, s1 = np.sort(seg @ u)
        side = 1 if inside(sim.world, (seg.mean(axis=0) + 1.0 * n)[None])[0] else -1
        along = edges.points_w @ u
        on = (np.abs(edges.points_w @ n - ln[0]) < 0.5) & (along >= s0) & (along <= s1)
        on &= water_side(ln, edges.sonar_w) == side
        if on.sum() < 150:
            continue
        # the metres of the wall seen (2 edges or more) and those a reference covers
        metres, counts = np.unique(np.floor(along[on]), return_counts=True)
        seen = metres[counts >= 2] + 0.5
        refs = of_wall.get(k, [])
        spans = sorted(tuple(np.sort(r.endpoints_w @ u)) for r in refs)
        covered = np.zeros(seen.size, dtype=bool)
        for lo, hi in spans:
            covered |= (seen >= lo) & (seen <= hi)
        assert covered.mean() >= 0.7, (k, covered.mean(), seen.size)
        assert all(b[0] >= a[1] - 0.5 for a, b in zip(spans[:-1], spans[1:], strict=True))


def test_robust_fit_ignores_second_returns_wake_and_clutter():
    """Two walls (y = 5 and x = 5, water at (25, 25)) of leading edges with sigma 0.2 m, 30 % of
    them second returns 2-4 m behind, a wake streak in the water seen once (5 s) and uniform
    clutter: two references, on the walls to 10 cm and 0.2 deg (the 2.5 m of the other wall at
    the corner, inside the fit band, pull a few cm)."""
    rng = np.random.default_rng(11)
    sonar_at = np.array([25.0, 25.0])
    pts, t = [], []
    for a, b, into_water in (
        ([5.0, 5.0], [85.0, 5.0], [0.0, 1.0]),
        ([5.0, 5.0], [5.0, 55.0], [1.0, 0.0]),
    ):
        s = rng.uniform(0.0, 1.0, 1500)
        off = rng.normal(0.0, 0.2, 1500)
        behind = rng.random(1500) < 0.3
        off[behind] = -rng.uniform(2.0, 4.0, behind.sum())
        pts.append(np.array(a) + np.outer(s, np.subtract(b, a)) + np.outer(off, into_water))
        t.append(T0_S + rng.uniform(0.0, 600.0, 1500))
    pts.append(np.column_stack([np.linspace(15.0, 45.0, 150), np.full(150, 17.0)]))  # wake
    t.append(T0_S + 300.0 + np.linspace(0.0, 5.0, 150))
    pts.append(rng.uniform([5.0, 5.0], [85.0, 55.0], (400, 2)))  # clutter
    t.append(T0_S + rng.uniform(0.0, 600.0, 400))
    p = np.concatenate(pts)
    walls = fit_walls(Edges(p, np.tile(sonar_at, (p.shape[0], 1)), np.concatenate(t)))
    assert len(walls) == 2
    found = sorted(walls, key=lambda w: -abs(np.cos(w.line_w[1])))  # x = 5 first, then y = 5
    for w, theta in zip(found, (0.0, np.pi / 2), strict=True):
        assert w.line_w[0] == pytest.approx(5.0, abs=0.1)
        assert abs(float(wrap_angle(w.line_w[1] - theta))) < np.deg2rad(0.2)
        assert w.side == 1  # the water is on the side of the normal, away from the origin
        assert w.length_m > 45.0


# -- statistics -------------------------------------------------------------------------------


def test_honest_lines_have_a_chi2_nees_and_no_bias():
    """4,000 lines drawn from their covariance about the true walls: NEES median 2 ln 2, mean 2,
    1 % beyond the 99 % gate; bias 0, scatter sigma (tolerances: 4 standard errors)."""
    cov = np.array([[0.3**2, 0.3 * 0.05 * 0.4], [0.3 * 0.05 * 0.4, 0.05**2]])
    lines, _, walls = drawn_lines(1, 4000, (0.0, 0.0, 0.0, 0.0), cov)
    o = quality_report(lines, walls)["overall"]
    assert o["n_matched"] == 4000
    assert o["nees_median"] == pytest.approx(2.0 * np.log(2.0), abs=0.13)
    assert o["nees_mean"] == pytest.approx(2.0, abs=0.13)
    assert o["outside_gate"] == pytest.approx(0.01, abs=0.0065)
    assert o["rho_bias_m"] == pytest.approx(0.0, abs=0.02)
    assert o["rho_sd_m"] == pytest.approx(0.3, abs=0.015)
    assert o["theta_sd_deg"] == pytest.approx(np.rad2deg(0.05), abs=0.15)
    assert o["claimed_sigma_rho_m"] == pytest.approx(0.3, rel=1e-9)


def test_biased_and_overconfident_lines_are_scored_not_dropped():
    """Per-wall biases (-1, 0, 1, 2 m) are found wall by wall; the pooled per-wall scatter is
    sigma while the overall one is not; the association is the same with the bias removed and
    with a covariance 100 times too small: it does not look at either."""
    cov = np.diag([0.4**2, np.deg2rad(2.0) ** 2])
    biases = (-1.0, 0.0, 1.0, 2.0)
    lines, which, walls = drawn_lines(2, 2000, biases, cov)
    rep = quality_report(lines, walls)
    assert rep["overall"]["n_matched"] == 2000
    for k, row in enumerate(rep["walls"]):
        assert row["rho_bias_m"] == pytest.approx(biases[k], abs=4 * 0.4 / np.sqrt(row["n"]))
    assert rep["overall"]["per_wall_scatter_rho_m"] == pytest.approx(0.4, abs=0.03)
    assert rep["overall"]["rho_sd_m"] > 1.0
    matches = [m.wall for m in associate(lines, walls)]
    assert matches == which.tolist()
    unbiased, _, _ = drawn_lines(2, 2000, (0.0,) * 4, cov)
    assert [m.wall for m in associate(unbiased, walls)] == matches
    tight = [
        LineFeature(f.t, f.wTr, f.rho_m, f.theta_rad, f.cov / 100.0, 20, f.endpoints_r, 20)
        for f in lines
    ]
    assert [m.wall for m in associate(tight, walls)] == matches
    # a line beyond the gates is counted, by reason
    far = drawn_lines(3, 1, (6.0, 6.0, 6.0, 6.0), cov)[0]
    assert quality_report(far, walls)["overall"]["unmatched"] == {"beyond distance gate": 1}
    assert (
        quality_report(far, walls, AssociationGates(max_distance_m=8.0))["overall"]["n_matched"]
        == 1
    )


def test_error_stats_of_known_values():
    e = np.array([[0.1, np.deg2rad(1.0)], [0.3, np.deg2rad(-1.0)], [0.5, np.deg2rad(3.0)]])
    P = np.tile(np.diag([0.04, np.deg2rad(2.0) ** 2]), (3, 1, 1))
    q = np.einsum("ki,kij,kj->k", e, np.linalg.inv(P), e)
    s = error_stats(e, q, P)
    assert s["n"] == 3
    assert s["rho_bias_m"] == pytest.approx(0.3, abs=1e-12)
    assert s["rho_sd_m"] == pytest.approx(0.2, abs=1e-12)
    assert s["theta_bias_deg"] == pytest.approx(1.0, abs=1e-12)
    assert s["claimed_sigma_rho_m"] == pytest.approx(0.2, abs=1e-12)
    assert s["nees_median"] == pytest.approx(float(np.median(q)), abs=1e-12)
    assert s["outside_gate"] == pytest.approx(float(np.mean(q > chi2_gate(2, 0.99))), abs=1e-12)
    assert error_stats(np.zeros((0, 2)), np.zeros(0), np.zeros((0, 2, 2)))["n"] == 0


def test_reprojection_separates_the_pose_error_from_the_line_error():
    """Exact measurements from the true poses, extracted on poses 2 m and 3 deg off (a closed
    loop's estimate): against the walls they are off in their own frames and exact once
    re-projected onto the true poses; both frames pair every line with its own wall."""
    rng = np.random.default_rng(5)
    walls = basin_walls()
    bTs = np.array([0.3, 0.0, np.pi])
    cov = np.diag([0.2**2, np.deg2rad(2.0) ** 2])
    t = T0_S + np.arange(200.0)
    which = rng.integers(0, 4, t.size)
    wTs = np.array([basin_pose(rng, walls[k]) for k in which])
    truth = Trajectory(t, compose(wTs, inverse(bTs)))
    lines = []
    for i, k in enumerate(which):
        exact = drawn_line(rng, walls[k], wTs[i], np.zeros((2, 2)), 0.0, t[i])
        off = wTs[i] + np.array([2.0, 0.0, np.deg2rad(3.0)])
        lines.append(
            LineFeature(t[i], off, exact.rho_m, exact.theta_rad, cov, 20, exact.endpoints_r, 20)
        )
    rep = evaluate_lines(lines, walls, truth, bTs)
    assert [ln["wall"] for ln in rep["own"]["lines"]] == which.tolist()
    assert [ln["wall"] for ln in rep["ruler"]["lines"]] == which.tolist()
    assert rep["ruler"]["overall"]["rho_rms_m"] == pytest.approx(0.0, abs=1e-6)
    assert rep["ruler"]["overall"]["theta_rms_deg"] == pytest.approx(0.0, abs=1e-6)
    assert rep["own"]["overall"]["theta_rms_deg"] == pytest.approx(3.0, abs=1e-6)
    assert rep["own"]["overall"]["rho_rms_m"] > 0.5
    placed = reproject(lines, truth, bTs)
    assert np.allclose([f.wTr for f in placed], wTs, atol=1e-9)


def test_scan_lines_take_out_a_ruler_error_that_lasts_a_scan():
    """For one scan the ruler puts the sonar 0.8 m off across the wall and turns it by 4 deg:
    the line it places and that scan's edges move together. Against the fitted wall the line
    is off by the ruler's error; against the wall as its own scan's edges show it, exact."""
    rng = np.random.default_rng(9)
    walls = basin_walls()
    bTs = np.zeros(3)
    wall = walls[0]  # y = 0, water above
    t_line = T0_S + 100.0
    true_pose = np.array([30.0, 10.0, 0.3])
    ruler_pose = true_pose + np.array([0.0, 0.8, np.deg2rad(4.0)])
    ruler = Trajectory(np.array([T0_S, T0_S + 200.0]), np.array([ruler_pose, ruler_pose]))
    exact = drawn_line(rng, wall, true_pose, np.zeros((2, 2)), 0.0, t_line)
    cov = np.diag([0.1**2, np.deg2rad(1.0) ** 2])
    line = LineFeature(
        t_line, true_pose, exact.rho_m, exact.theta_rad, cov, 20, exact.endpoints_r, 20
    )
    t_edges = T0_S + rng.uniform(90.0, 100.0, 200)  # the scan of the line (13.6 s)
    on_wall = np.column_stack([rng.uniform(10.0, 50.0, 200), rng.normal(0.0, 0.05, 200)])
    # the scan's edges as the ruler projects them: seen from the true pose, placed from its own
    pts = transform_points(compose(ruler_pose, inverse(true_pose)), on_wall)
    edges = Edges(pts, np.tile(ruler_pose[:2], (200, 1)), t_edges)
    placed = reproject([line], ruler, bTs)
    (scan_line,) = scan_lines(placed, associate(placed, walls), walls, edges, ScanReference(13.6))
    expected = line_world_to_frame(scan_line, ruler_pose)[0]
    assert np.allclose(expected, line_world_to_frame(wall.line_w, true_pose)[0], atol=0.03)
    rep = evaluate_lines([line], walls, ruler, bTs, scan=(edges, ScanReference(13.6)))
    own, ruled, scanned = (rep[k]["lines"][0] for k in ("own", "ruler", "ruler_scan"))
    assert own["e_rho_m"] == pytest.approx(0.0, abs=1e-9)
    assert ruled["e_theta_deg"] == pytest.approx(4.0, abs=1e-6)
    assert abs(ruled["e_rho_m"]) > 0.5
    assert scanned["e_rho_m"] == pytest.approx(0.0, abs=0.03)
    assert scanned["e_theta_deg"] == pytest.approx(0.0, abs=0.1)
    # no edges in the scan: unmatched, with the reason
    late = Edges(pts, edges.sonar_w, t_edges - 50.0)
    rep = evaluate_lines([line], walls, ruler, bTs, scan=(late, ScanReference(13.6)))
    assert rep["ruler_scan"]["overall"]["unmatched"] == {"too few edges in its scan": 1}


def test_lines_jsonl_round_trip_and_bad_rows(tmp_path):
    lines, _, _ = drawn_lines(4, 5, (0.0,) * 4, np.diag([0.1, 0.01]))
    path = tmp_path / "lines.jsonl"
    path.write_text(
        "".join(json.dumps({**f.to_json(), "landmark": i}) + "\n" for i, f in enumerate(lines))
    )
    back, extras = read_lines_jsonl(path)
    assert [e["landmark"] for e in extras] == list(range(5))
    for a, b in zip(lines, back, strict=True):
        assert np.allclose(a.endpoints_world(), b.endpoints_world(), atol=1e-9)
        assert np.allclose(a.wTr, b.wTr) and np.allclose(a.cov, b.cov) and a.rho_m == b.rho_m
    path.write_text(path.read_text().splitlines()[0] + "\n" + '{"t": 1.0}\n')
    with pytest.raises(DataError, match=r"lines.jsonl:2: not a line feature"):
        read_lines_jsonl(path)
    with pytest.raises(DataError, match="file not found"):
        read_lines_jsonl(tmp_path / "missing.jsonl")


def test_lines_jsonl_keeps_the_mounting_the_lines_were_extracted_with(tmp_path):
    # a back end reading the file back must be able to check its mounting against the lines'
    # (check_mounting); a file that dropped bTs would let a different mounting through unseen
    bTs = np.array([0.3, -0.1, np.pi])
    lines, _, _ = drawn_lines(4, 3, (0.0,) * 4, np.diag([0.1, 0.01]))
    lines = [replace(f, bTs=bTs) for f in lines]
    path = tmp_path / "lines.jsonl"
    path.write_text("".join(json.dumps({**f.to_json(), "landmark": 7}) + "\n" for f in lines))
    back, extras = read_lines_jsonl(path)
    assert all(b.bTs is not None and np.allclose(b.bTs, bTs, atol=1e-12) for b in back)
    assert extras == [{"landmark": 7}] * 3  # the feature's own fields are not extras
    check_mounting(back, bTs, "test")
    with pytest.raises(ValueError, match="sonar mounting"):
        check_mounting(back, np.zeros(3), "test")
    rows = path.read_text().splitlines()
    bad = json.loads(rows[1])
    bad["bTs"] = [0.3, "x"]
    path.write_text(rows[0] + "\n" + json.dumps(bad) + "\n")
    with pytest.raises(DataError, match=r"lines.jsonl:2: not a line feature: .*bTs"):
        read_lines_jsonl(path)


# -- the marina -------------------------------------------------------------------------------


def test_marina_references_are_walls_the_vehicle_never_crosses(marina):
    """The marina's references (GPS as a ruler): the two basins and the channel give at least
    18 walls over 700 m, the channel's straight west wall in one piece over 130 m, each sharp
    to under 1 m; the GPS track crosses none of them, so none sits in the water."""
    ruler = gps_ahrs_trajectory(marina)
    walls, edges = wall_references(marina, ruler)
    assert edges.t_s.size > 20000
    assert len(walls) >= 18
    assert sum(w.length_m for w in walls) > 700.0
    assert max(w.length_m for w in walls) > 130.0
    assert all(w.sigma_m < 1.0 for w in walls)
    track = ruler.poses(ruler.t_s)[:, :2]
    p, q = track[:-1], track[1:]
    for w in walls:
        a, b = w.endpoints_w
        # segments p-q and a-b cross when each one's ends lie on both sides of the other
        side_pq = np.sign(cross(b - a, p - a)) * np.sign(cross(b - a, q - a))
        side_ab = np.sign(cross(q - p, a - p)) * np.sign(cross(q - p, b - p))
        assert not np.any((side_pq < 0) & (side_ab < 0)), f"the GPS track crosses wall {w.index}"
