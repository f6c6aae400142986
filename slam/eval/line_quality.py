"""Line features against wall references: association, per-wall error statistics, NEES.

The references are :class:`sonarslam.slam.eval.walls.WallReference` (real data: fitted through the
GPS-projected leading edges) or the simulator's true walls (:func:`walls_from_segments`).

* **Association** (:func:`associate`), geometric and blind to the lines' covariances, so that a
  biased or over-confident line is scored, not dropped: a line may go to a wall when (i) the
  sonar (the origin of R) is on the wall's water side (a face is seen from its own side only),
  (ii) the line is within ``max_angle_rad`` of parallel to it, (iii) at least ``min_overlap`` of
  the line's segment, projected on the wall, lies within the wall's extent grown by
  ``extent_margin_m``; of those walls it goes to the nearest, the distance being the mean of the
  distances of the segment's two ends to the wall's line, if that is at most
  ``max_distance_m``. The defaults (5 m, 30 deg) are meant to lie beyond the spread of the
  lines about their walls, so that they only keep lines of other things out; the report gives
  the unmatched lines by reason and the counts at half and twice the gates, which show whether
  the gates decide anything. :func:`evaluate_lines` associates every line once, placed by the ruler
  (where the sonar was), and scores it against that wall in every frame, so that a pose error
  of the estimator cannot move a line to another wall or out of the gates.
* **Error** in each line's own frame R (:func:`sonarslam.slam.eval.lines.line_error_r`, sign-free):
  ``e = (rho - rho_wall, theta - theta_wall)`` with the wall's line taken into R by the pose
  of R. ``e_rho > 0``: the line lies beyond the wall's face as seen from the sonar.
* **NEES** ``e^T P^-1 e`` with the line's own covariance, and the statistics per wall and over
  all matched lines: :mod:`sonarslam.slam.eval.line_stats`.
* **Frames** (:func:`evaluate_lines`): the lines as their pose source placed them (``own``),
  re-projected onto the ruler at each line's time (``ruler``), and the same against the wall
  as the line's own scan's leading edges show it (``ruler_scan``, :func:`scan_lines`): the
  ruler's error that lasts a scan (a GPS offset, a heading error) is common to a line and the
  edges of its scan, so the truth about the lines lies between ``ruler`` (which charges that
  error to the lines) and ``ruler_scan`` (which also forgives what a line shares with its own
  scan's edges).

:func:`reproject` puts lines on another pose source (the GPS at each line's time): the
measurement ``(rho, theta)`` in R is what the sonar saw; the ruler only says where R was.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, replace
from typing import Any

import numpy as np
import numpy.typing as npt

from sonarslam.features.geometry import FloatArray, compose, wrap_angle
from sonarslam.features.line import LineFeature
from sonarslam.features.pose_source import PoseSource
from sonarslam.slam.eval.consistency import nees
from sonarslam.slam.eval.leading_edges import Edges
from sonarslam.slam.eval.line_stats import error_stats, pooled_sd
from sonarslam.slam.eval.lines import line_error_r
from sonarslam.slam.eval.truth import wall_lines_world
from sonarslam.slam.eval.walls import WallReference, robust_line_fit, water_side

__all__ = [
    "AssociationGates",
    "WallMatch",
    "walls_from_segments",
    "associate",
    "line_errors",
    "ScanReference",
    "scan_lines",
    "reproject",
    "quality_report",
    "evaluate_lines",
]


@dataclass(frozen=True)
class AssociationGates:
    """Gates of :func:`associate` (module docstring).

    Attributes
    ----------
    max_distance_m : float
        Largest mean distance of a line's segment ends to its wall's line (m).
    max_angle_rad : float
        Largest angle between a line and its wall (rad).
    min_overlap : float
        Smallest fraction of the line's segment inside the wall's grown extent.
    extent_margin_m : float
        The wall's extent is grown by this at both ends (m).
    """

    max_distance_m: float = 5.0
    max_angle_rad: float = float(np.deg2rad(30.0))
    min_overlap: float = 0.5
    extent_margin_m: float = 2.0

    def scaled(self, factor: float) -> AssociationGates:
        """Distance and angle gates times ``factor`` (the overlap rule unchanged)."""
        return replace(
            self,
            max_distance_m=self.max_distance_m * factor,
            max_angle_rad=self.max_angle_rad * factor,
        )

    def to_dict(self) -> dict[str, float]:
        return {**asdict(self), "max_angle_deg": float(np.rad2deg(self.max_angle_rad))}


@dataclass(frozen=True)
class WallMatch:
    """One line against the references.

    Attributes
    ----------
    wall : int or None
        Index of its wall in the list given to :func:`associate`; None when unmatched.
    reason : str
        ``"matched"``, ``"no wall"`` (none passes the side, angle and overlap rules) or
        ``"beyond distance gate"``.
    distance_m : float
        Mean distance of the segment's ends to the nearest candidate wall's line (m); NaN
        without a candidate.
    """

    wall: int | None
    reason: str
    distance_m: float


def walls_from_segments(segments_w: npt.ArrayLike, sides: npt.ArrayLike) -> list[WallReference]:
    """Known wall segments (the simulator's) as references.

    Parameters
    ----------
    segments_w : array_like, shape (W, 2, 2)
        Segments (world, m).
    sides : array_like of int, shape (W,)
        The water side of each (:attr:`WallReference.side`).
    """
    seg = np.asarray(segments_w, dtype=np.float64)
    lines = wall_lines_world(seg)
    return [
        WallReference(k, lines[k], seg[k].copy(), int(s), 0, 0.0, 0)
        for k, s in enumerate(np.asarray(sides, dtype=np.int64))
    ]


@dataclass(frozen=True)
class _WallFrame:
    """What :func:`_candidates` needs of a wall, computed once per wall rather than once per
    line and wall (the same values): its line, unit normal ``n`` and tangent ``u``, and its ends
    along ``u``, sorted."""

    rho_m: np.float64
    theta_rad: np.float64
    n: FloatArray
    u: FloatArray
    ends_u: tuple[float, float]
    side: int


def _wall_frames(walls: list[WallReference]) -> list[_WallFrame]:
    out = []
    for w in walls:
        line = np.asarray(w.line_w, dtype=np.float64)
        n = np.array([np.cos(w.line_w[1]), np.sin(w.line_w[1])])
        u = np.array([-n[1], n[0]])
        s0, s1 = np.sort(w.endpoints_w @ u)
        out.append(_WallFrame(line[0], line[1], n, u, (s0, s1), w.side))
    return out


def _candidates(
    ft: LineFeature, frames: list[_WallFrame], gates: AssociationGates
) -> tuple[list[int], FloatArray]:
    """Walls passing the side, angle and overlap rules, and every wall's mean end distance."""
    ends = ft.endpoints_world()
    theta_line = float(ft.line_world()[1])
    x, y = np.asarray(ft.wTr[:2], dtype=np.float64)
    dist = np.full(len(frames), np.inf)
    passing = []
    for k, w in enumerate(frames):
        dist[k] = float(np.mean(np.abs(ends @ w.n - w.rho_m)))
        # walls.water_side of the sonar's position, as line_side computes it: +1 where
        # rho - p . n < 0 (n = (cos theta, sin theta)), else -1
        side = 1 if w.rho_m - x * w.n[0] - y * w.n[1] < 0.0 else -1
        if side != w.side:
            continue
        if 0.5 * abs(float(wrap_angle(2.0 * (theta_line - w.theta_rad)))) > gates.max_angle_rad:
            continue
        a, b = np.sort(ends @ w.u)
        s0, s1 = w.ends_u
        lo, hi = max(a, s0 - gates.extent_margin_m), min(b, s1 + gates.extent_margin_m)
        inside = (hi - lo) / (b - a) if b - a > 1e-9 else float(s0 <= a <= s1)
        if inside >= gates.min_overlap:
            passing.append(k)
    return passing, dist


def associate(
    features: list[LineFeature],
    walls: list[WallReference],
    gates: AssociationGates | None = None,
) -> list[WallMatch]:
    """Each line against the references (module docstring).

    Parameters
    ----------
    features : list of LineFeature
        With their world poses ``wTr`` (and world segment ends) in the references' frame.
    walls : list of WallReference
    gates : AssociationGates, optional

    Returns
    -------
    list of WallMatch
        One per feature, in order.
    """
    g = gates or AssociationGates()
    frames = _wall_frames(walls)
    out = []
    for ft in features:
        passing, dist = _candidates(ft, frames, g)
        if not passing:
            out.append(WallMatch(None, "no wall", float("nan")))
            continue
        k = min(passing, key=lambda j: dist[j])
        ok = dist[k] <= g.max_distance_m
        out.append(
            WallMatch(
                k if ok else None, "matched" if ok else "beyond distance gate", float(dist[k])
            )
        )
    return out


def line_errors(
    features: list[LineFeature],
    matches: list[WallMatch],
    walls: list[WallReference],
    references_w: FloatArray | None = None,
) -> tuple[FloatArray, FloatArray]:
    """Errors in R (N, 2) (m, rad) and NEES (N,) of lines against their matched walls (NaN
    where unmatched); the module docstring says which error and which NEES.

    ``references_w`` (N, 2): each line's own reference world line instead of its wall's
    (:func:`scan_lines`)."""
    E = np.full((len(features), 2), np.nan)
    Q = np.full(len(features), np.nan)
    for i, (ft, m) in enumerate(zip(features, matches, strict=True)):
        if m.wall is not None:
            line_w = walls[m.wall].line_w if references_w is None else references_w[i]
            E[i] = line_error_r(ft, line_w)
            Q[i] = float(nees(E[i][None], ft.cov[None])[0])
    return E, Q


@dataclass(frozen=True)
class ScanReference:
    """How :func:`scan_lines` fits the wall as one scan of the ruler shows it.

    Attributes
    ----------
    window_s : float
        The scan: edges in ``[t - window_s, t]`` of a line at ``t`` (one turn of the head).
    band_m : float
        Edges within this of the wall's reference (m).
    margin_m : float
        Along the wall, edges within the line's segment grown by this (m).
    min_edges : int
        Fewer edges: no scan reference.
    min_span_m : float
        Edges spread along the wall over less than this (m): no scan reference.
    loss_scale_m : float
        Cauchy loss of the fit (:func:`sonarslam.slam.eval.walls.robust_line_fit`).
    """

    window_s: float
    band_m: float = 2.5
    margin_m: float = 2.0
    min_edges: int = 10
    min_span_m: float = 5.0
    loss_scale_m: float = 0.5


def scan_lines(
    placed: list[LineFeature],
    matches: list[WallMatch],
    walls: list[WallReference],
    edges: Edges,
    config: ScanReference,
) -> FloatArray:
    """Each line's wall as the ruler showed it during the line's own scan (world lines).

    The leading edges of the line's wall seen from its water side in ``[t - window_s, t]``
    (the scan the line was voted from), within ``band_m`` of the wall's reference and along it
    within the line's segment grown by ``margin_m``, fitted robustly. A ruler error that lasts
    the scan (a GPS offset, a heading error: a rigid motion of the scan about the sonar) moves
    these edges as it moves the line placed by the ruler at ``t``, so it drops out of the
    error against this line; so does whatever the line shares with its own scan's edges.

    Returns
    -------
    ndarray, shape (N, 2)
        ``(rho_m, theta_rad)`` in the world; NaN rows for unmatched lines and where the scan
        has fewer than ``min_edges`` edges or they span less than ``min_span_m``.
    """
    out = np.full((len(placed), 2), np.nan)
    for i, (ft, m) in enumerate(zip(placed, matches, strict=True)):
        if m.wall is None:
            continue
        w = walls[m.wall]
        n = np.array([np.cos(w.line_w[1]), np.sin(w.line_w[1])])
        u = np.array([-n[1], n[0]])
        s = np.sort(ft.endpoints_world() @ u)
        idx = np.flatnonzero((edges.t_s >= ft.t - config.window_s) & (edges.t_s <= ft.t))
        p = edges.points_w[idx]
        along = p @ u
        keep = (
            (np.abs(p @ n - w.line_w[0]) <= config.band_m)
            & (along >= s[0] - config.margin_m)
            & (along <= s[1] + config.margin_m)
            & (water_side(w.line_w, edges.sonar_w[idx]) == w.side)
        )
        if keep.sum() >= config.min_edges and np.ptp(along[keep]) >= config.min_span_m:
            out[i] = robust_line_fit(p[keep], w.line_w, config.loss_scale_m)
    return out


def reproject(
    features: list[LineFeature], pose_source: PoseSource, sonar_mounting_bTs: npt.ArrayLike
) -> list[LineFeature]:
    """The same measurements with frame R from another pose source at each line's time.

    Parameters
    ----------
    features : list of LineFeature
    pose_source : PoseSource
        Body poses (e.g. GPS + AHRS).
    sonar_mounting_bTs : array_like, shape (3,)

    Returns
    -------
    list of LineFeature
        ``wTr = pose_source(t) * bTs``; ``(rho, theta)``, ``cov`` and the segment in R unchanged.
    """
    if not features:
        return []
    t = np.array([f.t for f in features])
    wTr = compose(pose_source.poses(t), np.asarray(sonar_mounting_bTs, dtype=np.float64))
    return [replace(f, wTr=wTr[i]) for i, f in enumerate(features)]


def quality_report(
    features: list[LineFeature],
    walls: list[WallReference],
    gates: AssociationGates | None = None,
    placed: list[LineFeature] | None = None,
    scan: tuple[Edges, ScanReference] | None = None,
) -> dict[str, Any]:
    """Association and statistics of a set of lines against references.

    Parameters
    ----------
    features : list of LineFeature
        Scored in their frames R as given.
    walls : list of WallReference
    gates : AssociationGates, optional
    placed : list of LineFeature, optional
        The same lines, in the same order, as placed for the association (re-projected onto the
        ruler, :func:`reproject`); default ``features``.
    scan : (Edges, ScanReference), optional
        The ruler's leading edges and how to fit them: each line is scored against its wall as
        its own scan's edges show it (:func:`scan_lines`); lines without enough edges there are
        unmatched (``"too few edges in its scan"``).

    Returns
    -------
    dict
        ``overall``: :func:`error_stats` of all matched lines, with ``n_lines``, ``n_matched``,
        ``unmatched`` (count by reason), ``per_wall_scatter_rho_m`` and
        ``per_wall_scatter_theta_deg`` (pooled within walls), ``matched_at_half_gates`` and
        ``matched_at_double_gates``, ``distance_p90_m`` (90th percentile of the matched lines'
        end distances); ``walls``: one row per reference with its :func:`error_stats`;
        ``lines``: per line ``t``, ``wall`` (None: unmatched), ``reason``, ``distance_m``,
        ``e_rho_m``, ``e_theta_deg``, ``nees``; ``gates``.
    """
    g = gates or AssociationGates()
    where = features if placed is None else placed
    if len(where) != len(features):
        raise ValueError(f"placed has {len(where)} lines, features {len(features)}")
    matches = associate(where, walls, g)
    refs = None
    if scan is not None:
        refs = scan_lines(where, matches, walls, scan[0], scan[1])
        matches = [
            WallMatch(None, "too few edges in its scan", m.distance_m)
            if m.wall is not None and not np.isfinite(r[0])
            else m
            for m, r in zip(matches, refs, strict=True)
        ]
    E, Q = line_errors(features, matches, walls, refs)
    ok = np.array([m.wall is not None for m in matches], dtype=bool)
    wall_of = np.array([-1 if m.wall is None else m.wall for m in matches], dtype=np.int64)
    C = np.array([f.cov for f in features]).reshape(-1, 2, 2)
    overall = error_stats(E[ok], Q[ok], C[ok])
    pooled = pooled_sd(E[ok], wall_of[ok])
    reasons: dict[str, int] = {}
    for m in matches:
        if m.wall is None:
            reasons[m.reason] = reasons.get(m.reason, 0) + 1
    dist = np.array([m.distance_m for m in matches])

    def n_matched(factor: float) -> int:
        return sum(m.wall is not None for m in associate(where, walls, g.scaled(factor)))

    overall.update(
        {
            "n_lines": len(features),
            "n_matched": int(ok.sum()),
            "unmatched": reasons,
            "per_wall_scatter_rho_m": float(pooled[0]),
            "per_wall_scatter_theta_deg": float(np.rad2deg(pooled[1])),
            "matched_at_half_gates": n_matched(0.5),
            "matched_at_double_gates": n_matched(2.0),
            "distance_p90_m": float(np.percentile(dist[ok], 90)) if ok.any() else float("nan"),
        }
    )
    rows = []
    for k, w in enumerate(walls):
        mine = ok & (wall_of == k)
        rows.append(
            {"wall": w.index, "length_m": w.length_m, **error_stats(E[mine], Q[mine], C[mine])}
        )
    per_line = [
        {
            "t": f.t,
            "wall": m.wall,
            "reason": m.reason,
            "distance_m": _finite_or_none(m.distance_m),
            "e_rho_m": _finite_or_none(E[i, 0]),
            "e_theta_deg": _finite_or_none(np.rad2deg(E[i, 1])),
            "nees": _finite_or_none(Q[i]),
        }
        for i, (f, m) in enumerate(zip(features, matches, strict=True))
    ]
    return {"overall": overall, "walls": rows, "lines": per_line, "gates": g.to_dict()}


def _finite_or_none(x: float) -> float | None:
    return float(x) if np.isfinite(x) else None


def evaluate_lines(
    features: list[LineFeature],
    walls: list[WallReference],
    ruler: PoseSource | None = None,
    sonar_mounting_bTs: npt.ArrayLike | None = None,
    gates: AssociationGates | None = None,
    scan: tuple[Edges, ScanReference] | None = None,
) -> dict[str, dict[str, Any]]:
    """:func:`quality_report` of a set of lines in several frames.

    * ``"own"``: R where the pose source that extracted the lines put it;
    * ``"ruler"`` (given a ruler and the sonar mounting): R where the ruler puts the sonar at
      each line's time (:func:`reproject`);
    * ``"ruler_scan"`` (given also ``scan``, the ruler's edges and how to fit them): as
      ``"ruler"``, each line against its wall as its own scan's edges show it
      (:func:`scan_lines`).

    With a ruler, every frame associates the lines as placed by the ruler (module docstring).
    """
    if ruler is None:
        return {"own": quality_report(features, walls, gates)}
    if sonar_mounting_bTs is None:
        raise ValueError("re-projecting onto a ruler needs the sonar mounting")
    placed = reproject(features, ruler, sonar_mounting_bTs)
    out = {
        "own": quality_report(features, walls, gates, placed),
        "ruler": quality_report(placed, walls, gates),
    }
    if scan is not None:
        out["ruler_scan"] = quality_report(placed, walls, gates, scan=scan)
    return out
