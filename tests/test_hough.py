"""Voting space, voting with the sonar model (eqs. 2-4) and winners (paper 2.4-2.5)."""

from __future__ import annotations

import numpy as np
import pytest

from sonarslam.features.geometry import normalize_line, wrap_angle
from sonarslam.features.hough import (
    HoughGrid,
    accumulate,
    auto_h_bearings,
    auto_p_angles,
    eq4_rho,
    find_winners,
    find_winners_reference,
    sonar_model_samples,
    vote_arc,
    vote_arc_compiled,
    vote_samples,
)

ALPHA = np.deg2rad(3.0)
BETA = np.deg2rad(25.0)


def _angle_diff(a: float, b: float) -> float:
    return float(abs(wrap_angle(a - b)))


def _wall_bins(
    rho_w: float,
    theta_w: float,
    sensors: np.ndarray,
    bearings_rad: np.ndarray,
    bin_m: float,
    rng: np.random.Generator,
    sigma_m: float = 0.0,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Axis returns of a wall ``(rho_w, theta_w)`` for beams from several sensor positions.

    Returns per-bin sensor x, y, bearing and range (quantised to bins), incidence <= BETA only.
    """
    xs, ys, bs, rs = [], [], [], []
    n = np.array([np.cos(theta_w), np.sin(theta_w)])
    for sx, sy in sensors:
        d = rho_w - sx * n[0] - sy * n[1]
        for b in bearings_rad:
            u = np.array([np.cos(b), np.sin(b)])
            cos_inc = u @ n * np.sign(d)
            if cos_inc <= np.cos(BETA):
                continue
            r = abs(d) / cos_inc + rng.normal(0.0, sigma_m)
            xs.append(sx)
            ys.append(sy)
            bs.append(b)
            rs.append(np.round(r / bin_m) * bin_m)
    return np.array(xs), np.array(ys), np.array(bs), np.array(rs)


def test_grid_cells_and_normalisation() -> None:
    grid = HoughGrid.from_resolution(np.deg2rad(1.8), 0.1, 50.0)
    assert grid.n_theta == 200 and grid.n_rho == 500
    assert grid.theta_res_rad == pytest.approx(np.deg2rad(1.8), abs=1e-12)
    # a negative rho is the line (-rho, theta + pi)
    assert grid.cell_of(-1.23, 0.3) == grid.cell_of(1.23, 0.3 - np.pi)
    rho, theta = grid.cell_center(grid.cell_of(4.56, -2.0))
    assert abs(rho - 4.56) <= 0.05 + 1e-12
    assert _angle_diff(float(theta), -2.0) <= 0.5 * grid.theta_res_rad + 1e-12
    assert grid.cell_of(50.01, 0.0) == -1
    # odd counts are refused: theta + pi must be a cell
    with pytest.raises(ValueError):
        HoughGrid(n_theta=7, n_rho=10, rho_res_m=0.1)


def test_eq4_samples_lie_on_lines_through_the_arc() -> None:
    rng = np.random.default_rng(3)
    n = 50
    x, y = rng.uniform(-5, 5, n), rng.uniform(-5, 5, n)
    bearing, rng_m = rng.uniform(-np.pi, np.pi, n), rng.uniform(1, 40, n)
    rho, theta, theta_h = sonar_model_samples(x, y, bearing, rng_m, ALPHA, BETA, 5, 7)
    assert rho.shape == theta.shape == (n, 5, 7)
    # eq. 2: the arc bearings span the beam width
    dh = theta_h[..., 0] - bearing[:, None]
    np.testing.assert_allclose(dh[:, 0], -ALPHA / 2, atol=1e-12)
    np.testing.assert_allclose(dh[:, -1], ALPHA / 2, atol=1e-12)
    # eq. 3: line normals within beta of the arc bearing
    assert np.all(np.abs(theta - theta_h) <= BETA + 1e-12)
    # eq. 4: the arc point at theta_h lies on the line (rho, theta)
    px = x[:, None, None] + rng_m[:, None, None] * np.cos(theta_h)
    py = y[:, None, None] + rng_m[:, None, None] * np.sin(theta_h)
    np.testing.assert_allclose(px * np.cos(theta) + py * np.sin(theta), rho, atol=1e-9)
    # the printed eq. 4 (cos(theta - theta_S)) puts the off-axis samples off the arc
    printed = x[:, None, None] * np.cos(theta) + y[:, None, None] * np.sin(theta)
    printed = printed + rng_m[:, None, None] * np.cos(theta - bearing[:, None, None])
    off = np.abs(printed - rho)
    np.testing.assert_allclose(off[:, 2, :], 0.0, atol=1e-9)  # h = centre: the same
    assert off[:, 0, :].max() > 0.1  # edges of the arc: not the same
    # eq4_rho is the function used
    np.testing.assert_allclose(
        eq4_rho(x[:, None, None], y[:, None, None], theta, rng_m[:, None, None], theta_h),
        rho,
        atol=1e-12,
    )


@pytest.mark.parametrize("model", ["arc", "samples"])
def test_one_vote_per_cell_per_bin(model: str) -> None:
    rng = np.random.default_rng(5)
    grid = HoughGrid.from_resolution(np.deg2rad(1.8), 0.1, 20.0)
    n = 200
    # sensors near the origin so that many lines pass close to rho = 0 (the flip)
    x, y = rng.uniform(-2, 2, n), rng.uniform(-2, 2, n)
    bearing, rng_m = rng.uniform(-np.pi, np.pi, n), rng.uniform(0.5, 15, n)
    if model == "arc":
        votes = vote_arc(x, y, bearing, rng_m, grid, ALPHA, BETA)
    else:
        votes = vote_samples(x, y, bearing, rng_m, grid, ALPHA, BETA, 15, 40)
    key = votes.bin_index * grid.n_cells + votes.cell
    assert np.unique(key).size == key.size
    assert votes.cell.min() >= 0 and votes.cell.max() < grid.n_cells
    # a single bin fills the accumulator with 0 or 1
    one = vote_arc(x[:1], y[:1], bearing[:1], rng_m[:1], grid, ALPHA, BETA)
    acc = accumulate(one, grid)
    assert acc.max() == 1 and acc.sum() == one.cell.size


@pytest.mark.parametrize("seed", range(4))
def test_the_compiled_arc_votes_are_the_numpy_reference(seed: int) -> None:
    """:func:`vote_arc_compiled` against :func:`vote_arc` (the reference): the same votes in the
    same order, so the same accumulator, on random bins near and far (the rho flip, bearings
    across -pi), on two grids and sonar models, and on no bins at all."""
    rng = np.random.default_rng(seed)
    grids = [
        HoughGrid.from_resolution(np.deg2rad(1.8), 0.1, 20.0),
        HoughGrid.from_resolution(np.deg2rad(0.9), 0.3, 50.0),
    ]
    for grid, (alpha, beta) in zip(
        grids, [(ALPHA, BETA), (np.deg2rad(6.0), np.deg2rad(40.0))], strict=True
    ):
        n = int(rng.integers(1, 2000))
        x, y = rng.uniform(-3, 3, n), rng.uniform(-3, 3, n)
        bearing = rng.uniform(-np.pi, np.pi, n)
        bearing[: n // 10] = -np.pi  # on the wrap
        rng_m = rng.uniform(0.2, grid.n_rho * grid.rho_res_m, n)
        ref = vote_arc(x, y, bearing, rng_m, grid, alpha, beta)
        got = vote_arc_compiled(x, y, bearing, rng_m, grid, alpha, beta)
        assert got.n_bins == ref.n_bins == n
        assert np.array_equal(got.bin_index, ref.bin_index)
        assert np.array_equal(got.cell, ref.cell)
        assert np.array_equal(accumulate(got, grid), accumulate(ref, grid))
    empty = np.empty(0)
    none = vote_arc_compiled(empty, empty, empty, empty, grids[0], ALPHA, BETA)
    assert none.n_bins == 0 and none.cell.size == 0
    for vote in (vote_arc, vote_arc_compiled):  # a NaN is refused by name, by both
        bad = bearing.copy()
        bad[1] = np.nan
        with pytest.raises(ValueError, match="bearing_rad holds a non-finite value"):
            vote(x, y, bad, rng_m, grids[1], alpha, beta)


@pytest.mark.parametrize("seed", range(4))
def test_the_compiled_winners_are_the_numpy_reference(seed: int) -> None:
    """:func:`find_winners` (compiled) against :func:`find_winners_reference` on random and
    walled votes, with and without suppression windows: the same winners, voters and removed
    bins, best first."""
    rng = np.random.default_rng(seed)
    grid = HoughGrid.from_resolution(np.deg2rad(1.8), 0.2, 30.0)
    sensors = rng.uniform(-1.0, 1.0, (3, 2))
    x, y, b, r = _wall_bins(8.0, 0.4, sensors, np.linspace(-np.pi, np.pi, 200), 0.2, rng, 0.05)
    x2, y2, b2, r2 = _wall_bins(5.0, 2.2, sensors, np.linspace(-np.pi, np.pi, 200), 0.2, rng)
    n = 150
    cols = [np.concatenate([u, v, rng.uniform(lo, hi, n)]) for u, v, lo, hi in zip(
        (x, y, b, r), (x2, y2, b2, r2), (-1, -1, -np.pi, 1), (1, 1, np.pi, 25), strict=True
    )]  # fmt: skip
    votes = vote_arc(*cols, grid, ALPHA, BETA)
    for min_votes, sup_t, sup_r, most in [
        (5, 1, 1, 32),
        (3, 0, 0, 4),
        (12, 2, 3, 32),
        (1, 1, 2, 1000),
    ]:
        got, acc = find_winners(votes, grid, min_votes, most, sup_t, sup_r)
        ref, acc_ref = find_winners_reference(votes, grid, min_votes, most, sup_t, sup_r)
        assert np.array_equal(acc, acc_ref) and len(got) == len(ref) > 0
        for g, w in zip(got, ref, strict=True):
            assert (g.cell, g.votes, g.rho_m, g.theta_rad) == (
                w.cell,
                w.votes,
                w.rho_m,
                w.theta_rad,
            )
            assert np.array_equal(g.voters, w.voters) and np.array_equal(g.removed, w.removed)
    empty = vote_arc(np.empty(0), np.empty(0), np.empty(0), np.empty(0), grid, ALPHA, BETA)
    assert find_winners(empty, grid, 1)[0] == [] == find_winners_reference(empty, grid, 1)[0]


def test_arc_votes_are_the_limit_of_the_samples() -> None:
    rng = np.random.default_rng(11)
    grid = HoughGrid.from_resolution(np.deg2rad(1.8), 0.1, 30.0)
    n = 60
    x, y = rng.uniform(-3, 3, n), rng.uniform(-3, 3, n)
    bearing, rng_m = rng.uniform(-np.pi, np.pi, n), rng.uniform(2, 25, n)
    arc = vote_arc(x, y, bearing, rng_m, grid, ALPHA, BETA)
    dense = vote_samples(x, y, bearing, rng_m, grid, ALPHA, BETA, 101, 301)
    a = set((arc.bin_index * grid.n_cells + arc.cell).tolist())
    s = set((dense.bin_index * grid.n_cells + dense.cell).tolist())
    # dense samples converge to the arc votes, and (almost) never leave them
    assert len(a & s) / len(a | s) > 0.97
    assert len(s - a) / len(s) < 0.005
    # coarser (auto) sampling gives a subset of the arc votes
    h = auto_h_bearings(ALPHA, BETA, grid.rho_res_m, 30.0)
    p = auto_p_angles(BETA, grid.theta_res_rad)
    auto = vote_samples(x, y, bearing, rng_m, grid, ALPHA, BETA, h, p)
    sa = set((auto.bin_index * grid.n_cells + auto.cell).tolist())
    assert len(sa - a) / len(sa) < 0.005


@pytest.mark.parametrize("model", ["arc", "samples"])
@pytest.mark.parametrize(
    "sensors",
    [
        [(0.0, 0.0)],  # one sensor
        [(0.0, 0.0), (1.0, -0.5), (2.0, -1.0)],  # a moving sonar, re-referenced
        [(-3.0, 2.0), (-2.0, 4.0)],  # far off the origin
    ],
)
def test_single_wall_is_found_within_one_cell(model: str, sensors: list) -> None:
    rng = np.random.default_rng(7)
    grid = HoughGrid.from_resolution(np.deg2rad(0.9), 0.1, 30.0)
    rho_w, theta_w = 8.3, np.deg2rad(37.0)
    bearings = np.deg2rad(np.arange(-180.0, 180.0, 0.9))
    x, y, b, r = _wall_bins(rho_w, theta_w, np.array(sensors), bearings, 0.1, rng, 0.02)
    if model == "arc":
        votes = vote_arc(x, y, b, r, grid, ALPHA, BETA)
    else:
        h = auto_h_bearings(ALPHA, BETA, 0.1, 30.0)
        votes = vote_samples(
            x, y, b, r, grid, ALPHA, BETA, h, auto_p_angles(BETA, grid.theta_res_rad)
        )
    winners, _ = find_winners(votes, grid, min_votes=15)
    assert len(winners) >= 1
    w = winners[0]
    assert abs(w.rho_m - rho_w) <= grid.rho_res_m * 1.5
    assert _angle_diff(w.theta_rad, theta_w) <= grid.theta_res_rad * 1.5
    # the wall's bins all vote near the true line: most of them for the winner itself
    assert w.voters.size >= 0.7 * r.size


def test_winners_remove_their_voters_two_walls_two_lines() -> None:
    rng = np.random.default_rng(9)
    grid = HoughGrid.from_resolution(np.deg2rad(1.8), 0.1, 20.0)
    bearings = np.deg2rad(np.arange(-180.0, 180.0, 1.8))
    walls = [(5.0, np.deg2rad(10.0)), (3.0, np.deg2rad(-100.0))]
    parts = [_wall_bins(rw, tw, np.zeros((1, 2)), bearings, 0.1, rng, 0.01) for rw, tw in walls]
    x, y, b, r = (np.concatenate([p[i] for p in parts]) for i in range(4))
    wall_of = np.concatenate([np.full(p[0].size, k) for k, p in enumerate(parts)])
    votes = vote_arc(x, y, b, r, grid, ALPHA, BETA)
    winners, acc = find_winners(votes, grid, min_votes=10)
    assert acc.sum() == votes.cell.size
    assert len(winners) == 2
    found = sorted(winners, key=lambda w: -w.rho_m)
    for w, (rw, tw), k in zip(found, walls, range(2), strict=True):
        assert abs(w.rho_m - rw) <= 0.15
        assert _angle_diff(w.theta_rad, tw) <= np.deg2rad(2.7)
        assert np.all(wall_of[w.voters] == k)  # the voters are the wall's own bins
        assert set(w.voters.tolist()) <= set(w.removed.tolist())
    # no bin is a voter of two winners
    assert not set(found[0].removed.tolist()) & set(found[1].removed.tolist())
    # votes are counted once per bin: the winners' votes are their voter counts
    assert all(w.votes == w.voters.size for w in winners)


def test_negative_rho_votes_are_flipped() -> None:
    """A bin whose lines pass on both sides of R's origin votes at theta and theta + pi."""
    grid = HoughGrid.from_resolution(np.deg2rad(1.8), 0.1, 10.0)
    # sensor at (-2, 0) looking along +x at range 2: the arc passes through R's origin
    votes = vote_arc(
        np.array([-2.0]), np.array([0.0]), np.array([0.0]), np.array([2.0]), grid, ALPHA, BETA
    )
    rho, theta = grid.cell_center(votes.cell)
    assert rho.min() < 0.1
    # lines with normal near 0 and near pi (the flipped ones), all with small rho
    near0 = np.abs(wrap_angle(theta)) < BETA + ALPHA
    nearpi = np.abs(wrap_angle(theta - np.pi)) < BETA + ALPHA
    assert near0.any() and nearpi.any() and np.all(near0 | nearpi)
    assert rho.max() < 2.0 * np.sin(BETA + ALPHA) + 0.2
    # every voted line (at its cell centre) passes within a cell of the arc
    rn, tn = normalize_line(rho, theta)
    arc_b = np.linspace(-ALPHA / 2, ALPHA / 2, 201)
    px, py = -2.0 + 2.0 * np.cos(arc_b), 2.0 * np.sin(arc_b)
    dist = np.abs(px[None] * np.cos(tn)[:, None] + py[None] * np.sin(tn)[:, None] - rn[:, None])
    assert dist.min(axis=1).max() <= grid.rho_res_m + 2.0 * grid.theta_res_rad
