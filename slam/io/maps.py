"""Map pictures: sonar bins projected into the world, trajectories, line segments with their
95 % bands, and on simulated data the true walls and the true trajectory.

Every map shows all it draws (the bins, the trajectories, the segments, plus a margin): a
landmark or a beam the run reports is never cropped out (a landmark's segment is bounded by
the bins that show it, :func:`seen_extent`); the figure takes the data's aspect, and the
legend sits outside the axes.
Matplotlib's object interface (``Figure``): importing this module changes no global state.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import matplotlib.patheffects as path_effects
import numpy as np
from matplotlib.axes import Axes
from matplotlib.collections import LineCollection, PolyCollection
from matplotlib.figure import Figure
from matplotlib.patches import Rectangle
from scipy.stats import chi2

from sonarslam.features.geometry import FloatArray, transform_points
from sonarslam.features.line import LineFeature
from sonarslam.slam.io.trajectory import Trajectory

__all__ = [
    "TRAJECTORY_STYLES",
    "TrajectoryStyle",
    "trajectory_style",
    "MapLayers",
    "data_box",
    "draw_map",
    "plot_map",
    "plot_scans",
    "plot_lines",
    "segment_band_world",
    "landmark_band_world",
    "landmark_layers",
]


@dataclass(frozen=True)
class TrajectoryStyle:
    """How a trajectory is drawn: its colour, line style and legend name."""

    colour: str | None
    linestyle: str | tuple[float, tuple[float, ...]]
    label: str


#: How each trajectory name is drawn: the colours of Okabe and Ito's palette ("Color Universal
#: Design", 2008: told apart with every common colour-vision deficiency) and a line style of its
#: own, so that two estimates drawn over each other stay apart in grey as well.
TRAJECTORY_STYLES: dict[str, TrajectoryStyle] = {
    "truth": TrajectoryStyle("#000000", "-", "truth (simulator)"),
    "gps": TrajectoryStyle("#7f7f7f", "--", "GPS + AHRS"),
    "dr": TrajectoryStyle("#D55E00", "-.", "dead reckoning"),
    "ekf": TrajectoryStyle("#0072B2", "-", "EKF"),
    "isam2": TrajectoryStyle("#009E73", "-", "iSAM2 (online)"),
    "isam2_smoothed": TrajectoryStyle("#CC79A7", (0, (6, 1.5, 1, 1.5, 1, 1.5)), "iSAM2 smoothed"),
    "isam2_batch": TrajectoryStyle("#56B4E9", ":", "iSAM2 batch"),
    "isam2_redecided": TrajectoryStyle("#E69F00", (0, (8, 2)), "iSAM2 lines re-decided"),
    # the palette's eighth colour, its yellow, is too faint on white: black, dashed unlike the
    # truth's solid line
    "isam2_offline": TrajectoryStyle("#000000", (0, (4, 1.5, 1, 1.5)), "iSAM2 offline"),
}


def trajectory_style(name: str) -> TrajectoryStyle:
    """:data:`TRAJECTORY_STYLES`'s style of ``name``; another name: matplotlib's next colour,
    a solid line and the name itself."""
    return TRAJECTORY_STYLES.get(name, TrajectoryStyle(None, "-", name))


@dataclass(frozen=True)
class MapLayers:
    """What a map draws, bottom to top.

    Attributes
    ----------
    points_w : ndarray, shape (N, 2)
        Projected sonar bins, world East-North (m).
    trajectories : dict of str to Trajectory
        Drawn in :data:`TRAJECTORY_STYLES` (``"truth"``, ``"gps"``, back-end names).
    segments_w : sequence of ndarray, shape (2, 2)
        Line segments (landmarks, features), world (m).
    bands_w : sequence of ndarray, shape (M, 2)
        Their 95 % band polygons (:func:`segment_band_world`).
    walls_w : ndarray, shape (W, 2, 2), optional
        The simulator's true walls.
    segment_label : str
        Legend name of the segments (``"landmark"``, ``"line"``).
    shaded : sequence of int
        Indices of the segments whose band is shaded; every band is drawn as a thin outline
        (a shaded band of every landmark hides the map).
    segment_ids : sequence
        Empty, or one name per segment written beside it (a landmark's ``map.json`` id, which
        ``lines.jsonl`` names).
    """

    points_w: FloatArray
    trajectories: dict[str, Trajectory] = field(default_factory=dict)
    segments_w: Sequence[FloatArray] = ()
    bands_w: Sequence[FloatArray] = ()
    walls_w: FloatArray | None = None
    segment_label: str = "landmark"
    shaded: Sequence[int] = ()
    segment_ids: Sequence[object] = ()


#: Colour of the segments and their bands: stands out on the grey-to-black bins and beside the
#: trajectories' colours (a white edge keeps it apart from the black walls).
SEGMENT_COLOUR = "#ff7f00"


def data_box(layers: MapLayers, margin: float = 0.04) -> tuple[FloatArray, FloatArray]:
    """Lower-left and upper-right corners (m) of what a map shows: everything it draws, the
    bins, the trajectories and the segments (a landmark the run reports is never cropped out:
    a run's map stopped at 7 m with its one landmark at 15 m), with a margin; not the true
    walls, which may stand where the run never went (drawn where they cross the box)."""
    parts = [tr.poses_wTb[:, :2] for tr in layers.trajectories.values() if tr.t_s.size]
    if layers.points_w.shape[0]:
        parts.append(layers.points_w)
    parts += [np.asarray(s, dtype=np.float64).reshape(-1, 2) for s in layers.segments_w]
    if not parts:
        return np.array([-1.0, -1.0]), np.array([1.0, 1.0])
    allp = np.concatenate(parts)
    lo, hi = allp.min(axis=0), allp.max(axis=0)
    pad = max(margin * float(np.max(hi - lo)), 0.1)
    return lo - pad, hi + pad


def _draw_points(ax: Axes, points_w: FloatArray, lo: FloatArray, hi: FloatArray) -> None:
    """Projected bins as a density image (log scale): walls are where many bins agree. The cell
    is 1/700 of the larger side (0.4 m on the marina, 2 cm in a pool); drawn over the bands."""
    inside = np.all((points_w >= lo) & (points_w <= hi), axis=1)
    if not np.any(inside):
        return
    cell_m = max(float(np.max(hi - lo)) / 700.0, 0.01)
    bins = np.maximum(((hi - lo) / cell_m).astype(int), 1)
    h, xe, ye = np.histogram2d(
        points_w[inside, 0], points_w[inside, 1], bins=bins, range=[[lo[0], hi[0]], [lo[1], hi[1]]]
    )
    # empty cells transparent: the bands drawn under the bins stay visible in the water and
    # never hide a wall
    ax.imshow(
        np.ma.masked_equal(np.log1p(h.T), 0.0),
        origin="lower",
        extent=(xe[0], xe[-1], ye[0], ye[-1]),
        cmap="Greys",
        interpolation="nearest",
        vmin=-0.15 * float(np.log1p(h).max()),
        vmax=max(float(np.log1p(h).max()) * 0.8, 1e-9),
        zorder=5,
    )


def _draw_trajectories(ax: Axes, trajectories: dict[str, Trajectory]) -> None:
    # references under the estimates, dead reckoning under the closed loops
    order = {"truth": 0, "gps": 1, "dr": 2}
    for name in sorted(trajectories, key=lambda n: order.get(n, 3)):
        tr = trajectories[name]
        style = trajectory_style(name)
        ref = name in ("truth", "gps")
        ax.plot(
            tr.poses_wTb[:, 0],
            tr.poses_wTb[:, 1],
            ls=style.linestyle,
            lw=1.2 if ref else 1.0,
            color=style.colour,
            label=style.label,
            zorder=10 + order.get(name, 3),
        )


def _draw_ids(
    ax: Axes,
    segments_w: Sequence[FloatArray],
    ids: Sequence[object],
    lo: FloatArray,
    hi: FloatArray,
) -> None:
    """Each segment's id at its middle (inside the box), haloed in white to read on the bins."""
    for segment, name in zip(segments_w, ids, strict=True):
        mid = np.asarray(segment, dtype=np.float64).mean(axis=0)
        if np.any(mid < lo) or np.any(mid > hi):
            continue
        ax.annotate(
            str(name),
            (float(mid[0]), float(mid[1])),
            fontsize=7,
            fontweight="bold",
            color="#8c3c00",
            ha="center",
            va="center",
            zorder=20,  # over the trajectories: a landmark seen from where the vehicle loitered
            path_effects=[path_effects.withStroke(linewidth=2.5, foreground="white")],
        )


def draw_map(ax: Axes, layers: MapLayers, box: tuple[FloatArray, FloatArray]) -> None:
    """Draw ``layers`` on ``ax`` limited to ``box`` (:func:`data_box`)."""
    lo, hi = box
    _draw_points(ax, layers.points_w, lo, hi)
    if layers.walls_w is not None:
        for k, wall in enumerate(np.asarray(layers.walls_w)):
            ax.plot(
                wall[:, 0],
                wall[:, 1],
                "--",
                color="tab:cyan",
                lw=1.3,
                label="true walls" if k == 0 else None,
                zorder=6,
            )
    if layers.bands_w:
        outlines = PolyCollection(
            list(layers.bands_w),
            fc="none",
            ec=SEGMENT_COLOUR,
            lw=0.6,
            alpha=0.9,
            zorder=7,
            label="95 % band of (ρ, θ)",
        )
        ax.add_collection(outlines, autolim=False)
        shaded = [layers.bands_w[i] for i in layers.shaded]
        if shaded:
            fill = PolyCollection(shaded, fc=SEGMENT_COLOUR, ec="none", alpha=0.3, zorder=1)
            ax.add_collection(fill, autolim=False)
    if layers.segments_w:
        n = len(layers.segments_w)
        lines = LineCollection(
            list(layers.segments_w),
            colors=SEGMENT_COLOUR,
            lw=1.8,
            zorder=8,
            label=f"{layers.segment_label}s ({n})",
            path_effects=[
                path_effects.Stroke(linewidth=3.0, foreground="white"),
                path_effects.Normal(),
            ],
        )
        ax.add_collection(lines, autolim=False)
        if layers.segment_ids:
            _draw_ids(ax, layers.segments_w, layers.segment_ids, lo, hi)
    _draw_trajectories(ax, layers.trajectories)
    ax.set_xlim(lo[0], hi[0])
    ax.set_ylim(lo[1], hi[1])
    ax.set_aspect("equal")
    ax.set_xlabel("East (m)")
    ax.set_ylabel("North (m)")
    ax.grid(True, lw=0.3, alpha=0.5)


def _map_figure(box: tuple[FloatArray, FloatArray], panels: int = 1) -> Figure:
    """A figure whose axes take the data's aspect, with room for the legend on the right."""
    span = box[1] - box[0]
    aspect = float(np.clip(span[1] / max(span[0], 1e-9), 0.35, 2.5))
    width = 6.0 * panels
    return Figure(
        figsize=(width + 2.6, min(6.0 * aspect, 11.0) + 0.8), dpi=130, layout="constrained"
    )


def plot_map(path: str | Path, layers: MapLayers, title: str) -> Path:
    """One map (:func:`draw_map`) cropped to the data, legend outside on the right."""
    box = data_box(layers)
    fig = _map_figure(box)
    ax = fig.subplots()
    draw_map(ax, layers, box)
    ax.set_title(title, fontsize="medium")
    if ax.get_legend_handles_labels()[0]:
        fig.legend(loc="outside right upper", fontsize="small")
    out = Path(path)
    fig.savefig(out, bbox_inches="tight")
    return out


def plot_scans(
    path: str | Path,
    points_w: FloatArray,
    trajectories: dict[str, Trajectory],
    title: str,
    walls_w: FloatArray | None = None,
) -> Path:
    """Projected sonar bins with the trajectories (and the true walls of a simulated run)."""
    return plot_map(path, MapLayers(points_w, trajectories, walls_w=walls_w), title)


def _densest_window(points_w: FloatArray, side_m: float) -> tuple[float, float]:
    """Centre of the ``side_m`` square holding most of ``points_w``: the point with the most
    others within ``side_m / 2`` in both axes, moved to the mean of those (so it lands where
    the points are, not between them)."""
    d = np.abs(points_w[:, None, :] - points_w[None, :, :]).max(axis=-1)
    near = d <= 0.5 * side_m
    best = int(np.argmax(near.sum(axis=1)))
    centre = points_w[near[best]].mean(axis=0)
    return float(centre[0]), float(centre[1])


def plot_lines(
    path: str | Path,
    layers: MapLayers,
    title: str,
    zoom_side_m: float | None = None,
) -> Path:
    """Line segments with their 95 % bands over the projected bins: everything (left) and a
    zoom (right) on the square of side ``zoom_side_m`` (default: a sixth of the larger side of
    the map) holding the most segment midpoints, where the bands are wide enough to see."""
    box = data_box(layers)
    fig = _map_figure(box, panels=2)
    axes = fig.subplots(1, 2)
    for ax in axes:
        draw_map(ax, layers, box)
    axes[0].set_title(title, fontsize="medium")
    if layers.segments_w:
        mids = np.array([0.5 * (seg[0] + seg[1]) for seg in layers.segments_w])
        lo, hi = box
        inside = np.all((mids >= lo) & (mids <= hi), axis=1)
        mids = mids[inside] if np.any(inside) else mids
        side = zoom_side_m if zoom_side_m is not None else max(float(np.max(hi - lo)) / 6.0, 1.0)
        cx, cy = _densest_window(mids[:2000], side)
        # the window inside the map when it fits
        cx, cy = (
            float(np.clip(c, a + 0.5 * side, max(a + 0.5 * side, b - 0.5 * side)))
            for c, a, b in zip((cx, cy), lo, hi, strict=True)
        )
        axes[1].set_xlim(cx - 0.5 * side, cx + 0.5 * side)
        axes[1].set_ylim(cy - 0.5 * side, cy + 0.5 * side)
        axes[1].set_title(
            f"zoom: {side:.3g} m x {side:.3g} m with the most segments", fontsize="medium"
        )
        axes[0].add_patch(
            Rectangle(
                (cx - 0.5 * side, cy - 0.5 * side), side, side, fill=False, ec="tab:blue", lw=0.8
            )
        )
    if axes[0].get_legend_handles_labels()[0]:
        fig.legend(
            *axes[0].get_legend_handles_labels(), loc="outside right upper", fontsize="small"
        )
    out = Path(path)
    fig.savefig(out, bbox_inches="tight")
    return out


def segment_band_world(
    feature: LineFeature,
    confidence: float = 0.95,
    n_along: int = 25,
    n_boundary: int = 72,
) -> FloatArray:
    """Polygon of the lines within the ``confidence`` ellipse of ``(rho, theta)``, over the segment.

    The ellipse is ``{z : (z - z0)^T cov^-1 (z - z0) <= chi2_2(confidence)}`` in R. Along the
    segment (``n_along`` points ``q(s) = rho n + s t`` between its ends, ``n`` the normal and ``t``
    the tangent), every line ``(rho_k, theta_k)`` of ``n_boundary`` samples of the ellipse's
    boundary meets the normal through ``q(s)`` at the signed offset
    ``lambda_k = (rho_k - q . n_k) / (n . n_k)``; the band is ``[min_k lambda_k, max_k lambda_k]``
    (exact, no linearisation; to first order its half width is
    ``sqrt(chi2 [1, -s] cov [1, -s]^T)``).

    Parameters
    ----------
    feature : LineFeature
    confidence : float
        Probability of the ellipse (0.95: ``chi2_2 = 5.991``).
    n_along, n_boundary : int
        Samples along the segment and on the ellipse boundary.

    Returns
    -------
    ndarray, shape (2 n_along, 2)
        Polygon in the world (m): one side of the band from the first end to the second,
        then the other side back.
    """
    rho, theta = feature.rho_m, feature.theta_rad
    n = np.array([np.cos(theta), np.sin(theta)])
    t = np.array([-n[1], n[0]])
    ends = np.asarray(feature.endpoints_r, dtype=np.float64)
    s = np.linspace(float(ends[0] @ t), float(ends[1] @ t), n_along)
    q = rho * n[None, :] + s[:, None] * t[None, :]  # (A, 2) points of the segment in R
    cov = 0.5 * (feature.cov + feature.cov.T)
    w, v = np.linalg.eigh(cov)
    root = v * np.sqrt(np.clip(w, 0.0, None))[None, :]  # cov = root root^T
    phi = np.linspace(0.0, 2.0 * np.pi, n_boundary, endpoint=False)
    u = np.stack([np.cos(phi), np.sin(phi)])  # (2, K)
    z = np.array([rho, theta])[:, None] + np.sqrt(chi2.ppf(confidence, 2)) * root @ u  # (2, K)
    nk = np.stack([np.cos(z[1]), np.sin(z[1])], axis=-1)  # (K, 2)
    denom = nk @ n  # (K,)
    lam = (z[0][None, :] - q @ nk.T) / denom[None, :]  # (A, K)
    lo, hi = lam.min(axis=1), lam.max(axis=1)
    side_a = q + hi[:, None] * n[None, :]
    side_b = q + lo[:, None] * n[None, :]
    poly_r = np.concatenate([side_a, side_b[::-1]])
    return transform_points(feature.wTr, poly_r)


def landmark_band_world(
    landmark: dict[str, Any], confidence: float = 0.95
) -> tuple[FloatArray, FloatArray]:
    """Segment (2, 2) and 95 % band polygon (M, 2) of a ``map.json`` landmark, world (m).

    The landmark's world line ``(rho, theta)`` with its covariance is a line feature seen from
    the world origin, so the band is :func:`segment_band_world`'s (exact: the envelope of the
    lines of the confidence ellipse, over the segment).
    """
    ends = np.asarray(landmark["endpoints"], dtype=np.float64)
    feature = LineFeature(
        t=0.0,
        wTr=np.zeros(3),
        rho_m=float(landmark["rho"]),
        theta_rad=float(landmark["theta"]),
        cov=np.asarray(landmark["cov"], dtype=np.float64),
        votes=0,
        endpoints_r=ends,
    )
    return ends, segment_band_world(feature, confidence)


def seen_extent(
    landmark: dict[str, Any],
    points_w: FloatArray,
    confidence: float = 0.95,
    min_half_width_m: float = 0.1,
    quantile: float = 0.01,
    min_points: int = 5,
) -> FloatArray:
    """The part of a ``map.json`` landmark's segment that the bins show: its ends (2, 2), world (m).

    The bins within the landmark's ``confidence`` half width in rho (``sqrt(chi2_1) sigma_rho``,
    at least ``min_half_width_m``) of its line and inside its segment support it; the segment
    is cut to the ``quantile`` and ``1 - quantile`` of their positions along the line. With
    fewer than ``min_points`` such bins the segment is returned as it is.
    """
    ends = np.asarray(landmark["endpoints"], dtype=np.float64)
    theta, rho = float(landmark["theta"]), float(landmark["rho"])
    n = np.array([np.cos(theta), np.sin(theta)])
    t = np.array([-n[1], n[0]])
    half = max(np.sqrt(chi2.ppf(confidence, 1) * float(landmark["cov"][0][0])), min_half_width_m)
    s_ends = np.sort(ends @ t)
    pts = np.asarray(points_w, dtype=np.float64).reshape(-1, 2)
    s = pts @ t
    near = (np.abs(pts @ n - rho) <= half) & (s >= s_ends[0]) & (s <= s_ends[1])
    if np.count_nonzero(near) < min_points:
        return ends
    lo, hi = np.quantile(s[near], [quantile, 1.0 - quantile])
    return np.stack([rho * n + lo * t, rho * n + hi * t])


def landmark_layers(
    landmarks: Sequence[dict[str, Any]],
    points_w: FloatArray | None = None,
) -> tuple[list[FloatArray], list[FloatArray]]:
    """Segments and 95 % bands of ``map.json`` landmarks (:func:`landmark_band_world`); with
    the map's bins, each segment (and its band) is bounded by what the bins show
    (:func:`seen_extent`)."""
    if points_w is not None:
        landmarks = [{**lm, "endpoints": seen_extent(lm, points_w).tolist()} for lm in landmarks]
    pairs = [landmark_band_world(lm) for lm in landmarks]
    return [p[0] for p in pairs], [p[1] for p in pairs]
