"""Wall references for real data: straight walls fitted through the leading edges of all scans.

On real data there are no true walls. A *ruler* stands in for them: the bins of every beam are
projected into the world with a pose source that is not estimated from the sonar (GPS + AHRS on
the marina), and the straight walls are fitted through them. The ruler only measures; nothing it
gives goes back into an estimator.

1. **Leading edges** (:mod:`sonarslam.slam.eval.leading_edges`): the nearest bin of each run of returns
   along each beam, where a wall's echo band begins.
2. **Projection** (:func:`sonarslam.slam.eval.leading_edges.leading_edge_points`) with the ruler, keeping
   where the sonar was: a face is seen from its own side only (its *water side*).
3. **Walls** (:func:`fit_walls`), round after round until no line holds ``min_points`` edges:

   a. RANSAC (:func:`skimage.measure.ransac`, seeded, on a random subset of at most
      ``ransac_sample`` live edges; samples are pairs of edges 2-30 m apart) finds the line with
      most edges within ``ransac_band_m``;
   b. its edges are split by the side the sonar saw them from, and cut into pieces along the
      line where they leave a gap over ``split_gap_m``;
   c. each piece is refitted robustly: the edges of its side within ``fit_band_m`` of the line
      over the piece's extent, a total-least-squares line ``p . n(theta) = rho`` with a Cauchy
      loss of scale ``loss_scale_m`` (:func:`scipy.optimize.least_squares`), so far echoes,
      second returns and the vehicle's own wake pull it little. A bent piece is cut into
      straight parts where the median of its edges (bins of ``bend_bin_m``) leaves a
      Douglas-Peucker chain by more than ``bend_tolerance_m``, and each part is refitted alike;
      a part's extent is the 1st to 99th percentile of its edges along its line;
   d. a part is a wall when it is at least ``min_length_m`` long with ``min_points`` edges, at
      least ``min_points_per_m`` per metre, seen in an effective number of at least ``min_sightings`` windows of
      ``sighting_window_s`` (wake and clutter are seen once, walls over and over), and when no
      earlier wall of its side, nearly parallel and overlapping it, lies within
      ``duplicate_m``: a face cannot be seen through another, so that is the same face
      displaced by the ruler's error while it lasted;
   e. the edges of its side within ``clear_band_m`` of each part (over its extent) are removed,
      and so are the RANSAC edges of the round, wall or not, so that the search ends.

The reference line is where the leading edges of a wall concentrate: the wall's face as the
sonar's first returns see it, through the ruler. Its ``sigma_m`` (1.4826 MAD of its edges'
distances) says how sharp the ruler is there, and :func:`ruler_wander` how far the ruler itself
moves the wall from one scan to the next (GPS and heading errors that last a scan).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import Any

import numpy as np
import numpy.typing as npt
from scipy.optimize import least_squares

from sonarslam.datasets.source import Dataset
from sonarslam.features.geometry import FloatArray, line_side, normalize_line, wrap_angle
from sonarslam.features.pose_source import PoseSource
from sonarslam.slam.eval.leading_edges import EdgeConfig, Edges, leading_edge_points

__all__ = [
    "WallFitConfig",
    "WallReference",
    "water_side",
    "robust_line_fit",
    "fit_walls",
    "ruler_edges",
    "wall_references",
    "ruler_wander",
]

_MAD_TO_SIGMA = 1.4826
_SAMPLE_SPAN_M = (2.0, 30.0)  # a RANSAC sample: two edges this far apart (likely one wall)
_MIN_BIN_POINTS = 10  # a bin of the centre curve needs this many edges


@dataclass(frozen=True)
class WallFitConfig:
    """Settings of the wall search (module docstring, step 3), for harbour walls seen by a
    Miniking-like head (0.1 m bins, tens of metres).

    Attributes
    ----------
    ransac_band_m : float
        RANSAC inlier distance (m).
    fit_band_m : float
        Edges within this of the RANSAC line enter the robust refit (m).
    loss_scale_m : float
        Scale of the Cauchy loss of the refit (m).
    clear_band_m : float
        Edges within this of a found wall are removed from the search (m).
    split_gap_m : float
        A gap along the line over this cuts a consensus set into pieces (m).
    bend_bin_m, bend_tolerance_m : float
        Bins of the centre curve and the Douglas-Peucker tolerance that cut a bent piece into
        straight parts (m).
    duplicate_m, duplicate_angle_rad : float
        A wall within this distance (m) and angle (rad) of an earlier one on the same side,
        overlapping it, is the same face (occluded) and dropped.
    min_length_m, min_points, min_points_per_m, min_sightings, sighting_window_s
        What makes a piece a wall (module docstring, 3d).
    max_trials : int
        RANSAC trials per round.
    ransac_sample : int
        RANSAC searches a random subset of at most this many live edges (its consensus set is
        then taken over all of them).
    max_walls : int
        Stop after this many walls.
    seed : int
        Of the RANSAC generator.
    """

    ransac_band_m: float = 1.0
    fit_band_m: float = 2.5
    loss_scale_m: float = 0.5
    clear_band_m: float = 2.5
    split_gap_m: float = 4.0
    bend_bin_m: float = 2.5
    bend_tolerance_m: float = 1.0
    duplicate_m: float = 4.0
    duplicate_angle_rad: float = float(np.deg2rad(10.0))
    min_length_m: float = 8.0
    min_points: int = 60
    min_points_per_m: float = 2.0
    min_sightings: float = 3.0
    sighting_window_s: float = 30.0
    max_trials: int = 2000
    ransac_sample: int = 5000
    max_walls: int = 100
    seed: int = 0

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)


@dataclass(frozen=True, eq=False)
class WallReference:
    """One straight wall of the ruler.

    Attributes
    ----------
    index : int
        Its number in the list (order of discovery: most edges first, roughly).
    line_w : ndarray, shape (2,)
        ``(rho_m, theta_rad)`` in the world, normalised.
    endpoints_w : ndarray, shape (2, 2)
        Ends of the wall (world, m).
    side : int
        +1 when the water (where the sonar saw it from) is on the side of the normal
        ``(cos theta, sin theta)``, i.e. ``p . n > rho`` there; else -1.
    n_points : int
        Leading edges within ``ransac_band_m`` of it over its extent.
    sigma_m : float
        1.4826 MAD of those edges' distances to the line (m).
    n_sightings : float
        Effective number of windows of ``sighting_window_s`` in which it was seen
        (:meth:`sonarslam.slam.eval.leading_edges.Edges.sightings`).
    """

    index: int
    line_w: FloatArray
    endpoints_w: FloatArray
    side: int
    n_points: int
    sigma_m: float
    n_sightings: float

    @property
    def length_m(self) -> float:
        return float(np.linalg.norm(self.endpoints_w[1] - self.endpoints_w[0]))

    def to_json(self) -> dict[str, Any]:
        return {
            "index": self.index,
            "rho_m": float(self.line_w[0]),
            "theta_rad": float(self.line_w[1]),
            "endpoints_w": self.endpoints_w.tolist(),
            "side": self.side,
            "length_m": self.length_m,
            "n_points": self.n_points,
            "sigma_m": self.sigma_m,
            "n_sightings": self.n_sightings,
        }

    @classmethod
    def from_json(cls, d: dict[str, Any]) -> WallReference:
        return cls(
            int(d["index"]),
            np.array([d["rho_m"], d["theta_rad"]], dtype=np.float64),
            np.asarray(d["endpoints_w"], dtype=np.float64).reshape(2, 2),
            int(d["side"]),
            int(d["n_points"]),
            float(d["sigma_m"]),
            float(d["n_sightings"]),
        )


def _line_of(origin: FloatArray, direction: FloatArray) -> FloatArray:
    """``(rho, theta)`` of the line through ``origin`` along ``direction``."""
    n = np.array([direction[1], -direction[0]])
    rho, theta = normalize_line(float(origin @ n), float(np.arctan2(n[1], n[0])))
    return np.array([float(rho), float(theta)])


def _normal(line: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Unit normal and tangent of a line ``(rho, theta)``."""
    n = np.array([np.cos(line[1]), np.sin(line[1])])
    return n, np.array([-n[1], n[0]])


def water_side(line_w: npt.ArrayLike, positions_w: npt.ArrayLike) -> npt.NDArray[np.int64]:
    """Side of a line ``(rho, theta)`` the positions (..., 2) are on: +1 on the side of its
    normal ``(cos theta, sin theta)`` (``p . n > rho``), else -1 (:attr:`WallReference.side`;
    :func:`sonarslam.features.geometry.line_side` with the other sign)."""
    p = np.asarray(positions_w, dtype=np.float64)
    line = np.broadcast_to(np.asarray(line_w, dtype=np.float64), p.shape)
    return np.where(line_side(line, p) < 0.0, 1, -1).astype(np.int64)  # the normal's side


def robust_line_fit(points_w: FloatArray, line: FloatArray, loss_scale_m: float) -> FloatArray:
    """Robust total-least-squares line ``(rho, theta)`` through points (N, 2), from ``line``:
    ``p . n(theta) - rho`` with a Cauchy loss of scale ``loss_scale_m``
    (:func:`scipy.optimize.least_squares`); normalised."""

    def residuals(z: FloatArray) -> FloatArray:
        return np.asarray(points_w @ np.array([np.cos(z[1]), np.sin(z[1])]) - z[0])

    sol = least_squares(residuals, line, loss="cauchy", f_scale=loss_scale_m)
    rho, theta = normalize_line(sol.x[0], sol.x[1])
    return np.array([float(rho), float(theta)])


def _pieces(along_m: FloatArray, gap_m: float) -> list[npt.NDArray[np.int64]]:
    """Indices of ``along_m`` cut where sorted neighbours are more than ``gap_m`` apart."""
    order = np.argsort(along_m)
    cuts = np.flatnonzero(np.diff(along_m[order]) > gap_m) + 1
    return [p for p in np.split(order, cuts) if p.size]


def _near(
    points_w: FloatArray, line: FloatArray, band_m: float, extent_m: tuple[float, float]
) -> npt.NDArray[np.bool_]:
    """Points within ``band_m`` of a line and, along it, inside ``extent_m``."""
    n, u = _normal(line)
    s = points_w @ u
    return (np.abs(points_w @ n - line[0]) <= band_m) & (s >= extent_m[0]) & (s <= extent_m[1])


def _straight_parts(
    P: FloatArray, near: npt.NDArray[np.int64], line: FloatArray, config: WallFitConfig
) -> list[tuple[float, float]]:
    """Extents (along ``line``) of the straight parts of a piece (module docstring, 3c).

    The piece's centre curve, the median distance of its edges to ``line`` in bins of
    ``bend_bin_m`` along it, is simplified by Douglas-Peucker
    (:func:`skimage.measure.approximate_polygon`) to ``bend_tolerance_m``; each segment of the
    result is a straight part. The two end bins are left out of the curve: at a corner they
    hold the edges of the other wall too, which bend the curve where the wall does not.
    """
    from skimage.measure import approximate_polygon  # lazy: scikit-image is a dev dependency

    n, u = _normal(line)
    s = P[near] @ u
    r = P[near] @ n - line[0]
    edges_s = np.arange(s.min(), s.max() + config.bend_bin_m, config.bend_bin_m)
    k = np.digitize(s, edges_s) - 1
    curve = [
        (float(np.median(s[k == b])), float(np.median(r[k == b])))
        for b in range(edges_s.size)
        if np.count_nonzero(k == b) >= _MIN_BIN_POINTS
    ]
    if len(curve) < 5:
        return [(float(s.min()), float(s.max()))]
    corners = approximate_polygon(np.array(curve[1:-1]), config.bend_tolerance_m)[:, 0]
    cuts = np.concatenate([[s.min()], corners[1:-1], [s.max()]])
    return [(float(a), float(b)) for a, b in zip(cuts[:-1], cuts[1:], strict=True)]


def _occluded(
    line: FloatArray, ends: FloatArray, side: int, walls: list[WallReference], config: WallFitConfig
) -> bool:
    """True when an earlier wall on the same side, within ``duplicate_angle_rad`` of parallel, overlaps
    this one along its length and lies within ``duplicate_m`` of it: one face cannot be seen
    through another, so this is the same face displaced by the ruler's error (or a bend)."""
    for w in walls:
        if w.side != side:
            continue
        if abs(float(wrap_angle(2.0 * (w.line_w[1] - line[1])))) > 2.0 * config.duplicate_angle_rad:
            continue
        n, u = _normal(w.line_w)
        s_w = np.sort(w.endpoints_w @ u)
        s = ends @ u
        lo, hi = max(s_w[0], s.min()), min(s_w[1], s.max())
        if hi <= lo:
            continue
        # this wall's points over the overlap, their distance to the earlier wall
        t = (np.array([lo, hi]) - s[0]) / (s[1] - s[0])
        over = ends[0] + t[:, None] * (ends[1] - ends[0])
        if np.all(np.abs(over @ n - w.line_w[0]) <= config.duplicate_m):
            return True
    return False


def _wall_from_part(
    edges: Edges,
    candidates: npt.NDArray[np.int64],
    line: FloatArray,
    extent_m: tuple[float, float],
    config: WallFitConfig,
) -> tuple[FloatArray, FloatArray, npt.NDArray[np.int64]] | None:
    """Robust line, ends and support (indices) of one straight part, or None if it is no wall
    (module docstring, 3c-d). ``candidates``: the live edges seen from the part's side."""
    P = edges.points_w
    near = candidates[_near(P[candidates], line, config.fit_band_m, extent_m)]
    if near.size < config.min_points:
        return None
    fitted = robust_line_fit(P[near], line, config.loss_scale_m)
    n, u = _normal(fitted)
    support = near[np.abs(P[near] @ n - fitted[0]) <= config.ransac_band_m]
    if support.size < config.min_points:
        return None
    s0, s1 = np.percentile(P[support] @ u, [1.0, 99.0])
    length = float(s1 - s0)
    if (
        length < config.min_length_m
        or support.size < config.min_points_per_m * length
        or edges.sightings(support, config.sighting_window_s) < config.min_sightings
    ):
        return None
    foot = fitted[0] * n
    return fitted, np.stack([foot + s0 * u, foot + s1 * u]), support


def _add_wall(
    edges: Edges,
    alive: npt.NDArray[np.bool_],
    found: tuple[FloatArray, FloatArray, npt.NDArray[np.int64]],
    walls: list[WallReference],
    config: WallFitConfig,
) -> None:
    """Append a wall unless occluded; clear the edges near it on its side either way."""
    fitted, ends, support = found
    P = edges.points_w
    n, u = _normal(fitted)
    side = 1 if water_side(fitted, edges.sonar_w[support]).sum() >= 0 else -1
    if not _occluded(fitted, ends, side, walls, config):
        r = P[support] @ n - fitted[0]
        walls.append(
            WallReference(
                index=len(walls),
                line_w=fitted,
                endpoints_w=ends,
                side=side,
                n_points=int(support.size),
                sigma_m=float(_MAD_TO_SIGMA * np.median(np.abs(r - np.median(r)))),
                n_sightings=edges.sightings(support, config.sighting_window_s),
            )
        )
    s_ends = ends @ u
    grown = (s_ends.min() - config.clear_band_m, s_ends.max() + config.clear_band_m)
    same_side = water_side(fitted, edges.sonar_w) == side
    alive &= ~(same_side & _near(P, fitted, config.clear_band_m, grown))
    alive[support] = False


def _round(
    edges: Edges,
    alive: npt.NDArray[np.bool_],
    consensus: npt.NDArray[np.int64],
    line: FloatArray,
    config: WallFitConfig,
    walls: list[WallReference],
) -> None:
    """The walls of one RANSAC consensus set (module docstring, 3b-e); updates ``alive``."""
    P = edges.points_w
    _, u = _normal(line)
    side = water_side(line, edges.sonar_w)
    for sd in (1, -1):
        mine = consensus[side[consensus] == sd]
        along = P[mine] @ u
        for piece in _pieces(along, config.split_gap_m):
            if piece.size < config.min_points:
                continue
            live = np.flatnonzero(alive & (side == sd))
            extent = (float(along[piece].min()), float(along[piece].max()))
            near = live[_near(P[live], line, config.fit_band_m, extent)]
            if near.size < config.min_points:
                continue
            fitted = robust_line_fit(P[near], line, config.loss_scale_m)
            for part in _straight_parts(P, near, fitted, config):
                found = _wall_from_part(edges, near[alive[near]], fitted, part, config)
                if found is not None:
                    _add_wall(edges, alive, found, walls, config)
    alive[consensus] = False


def fit_walls(edges: Edges, config: WallFitConfig | None = None) -> list[WallReference]:
    """Straight walls through leading edges (module docstring, step 3).

    Parameters
    ----------
    edges : Edges
        Leading edges in the world with where the sonar was (:func:`leading_edge_points`).
    config : WallFitConfig, optional

    Returns
    -------
    list of WallReference
        In the order found.
    """
    from skimage.measure import LineModelND, ransac  # lazy: scikit-image is a dev dependency

    cfg = config or WallFitConfig()
    rng = np.random.default_rng(cfg.seed)
    alive = np.ones(edges.t_s.size, dtype=bool)
    walls: list[WallReference] = []

    def sample_ok(x: FloatArray) -> bool:
        d = float(np.linalg.norm(x[1] - x[0]))
        return _SAMPLE_SPAN_M[0] <= d <= _SAMPLE_SPAN_M[1]

    while alive.sum() >= cfg.min_points and len(walls) < cfg.max_walls:
        idx = np.flatnonzero(alive)
        sample = idx if idx.size <= cfg.ransac_sample else rng.choice(idx, cfg.ransac_sample, False)
        model, inliers = ransac(
            edges.points_w[sample],
            LineModelND,
            min_samples=2,
            residual_threshold=cfg.ransac_band_m,
            is_data_valid=sample_ok,
            max_trials=cfg.max_trials,
            rng=rng,
        )
        if model is None or inliers is None:
            break
        line = _line_of(np.asarray(model.origin), np.asarray(model.direction))
        n, _ = _normal(line)
        consensus = idx[np.abs(edges.points_w[idx] @ n - line[0]) < cfg.ransac_band_m]
        if consensus.size < cfg.min_points:
            break
        _round(edges, alive, consensus, line, cfg, walls)
    return walls


def ruler_wander(
    edges: Edges,
    walls: list[WallReference],
    window_s: float,
    band_m: float = 2.5,
    min_edges: int = 5,
) -> FloatArray:
    """How far the ruler moves each wall between windows of time (m).

    For each wall, the edges seen from its water side within ``band_m`` of it (over its
    extent) are grouped in windows of ``window_s`` (a scan); the median signed distance of each
    window with at least ``min_edges`` edges is where the ruler put the wall then. Returns
    their standard deviation per wall, shape (W,) (NaN below two windows): the part of a line's
    measured error that may be the ruler's (GPS and heading errors lasting about a scan).
    """
    P = edges.points_w
    out = np.full(len(walls), np.nan)
    for k, w in enumerate(walls):
        n, u = _normal(w.line_w)
        s = np.sort(w.endpoints_w @ u)
        mine = _near(P, w.line_w, band_m, (float(s[0]), float(s[1])))
        mine &= water_side(w.line_w, edges.sonar_w) == w.side
        r = P[mine] @ n - w.line_w[0]
        win = np.floor(edges.t_s[mine] / window_s)
        medians = [
            float(np.median(r[win == v])) for v in np.unique(win) if (win == v).sum() >= min_edges
        ]
        if len(medians) >= 2:
            out[k] = float(np.std(medians, ddof=1))
    return out


def ruler_edges(dataset: Dataset, ruler: PoseSource, config: EdgeConfig | None = None) -> Edges:
    """The leading edges of all the beams of a dataset inside the navigation span and the
    ruler's span, projected with the ruler (GPS + AHRS on the marina)."""
    span = getattr(ruler, "span_s", None)
    beams = dataset.nav_beams()
    if span is not None:
        beams = beams.between(span[0], span[1])
    if not beams:
        raise ValueError(f"{dataset.root}: no sonar beam inside the ruler's span")
    return leading_edge_points(
        beams, dataset.config.sonar, dataset.config.sonar_mounting, ruler, config
    )


def wall_references(
    dataset: Dataset,
    ruler: PoseSource,
    edge_config: EdgeConfig | None = None,
    fit_config: WallFitConfig | None = None,
) -> tuple[list[WallReference], Edges]:
    """The walls of a dataset (:func:`fit_walls`) through its leading edges projected with the
    ruler (:func:`ruler_edges`); returns them and the edges."""
    edges = ruler_edges(dataset, ruler, edge_config)
    return fit_walls(edges, fit_config), edges
