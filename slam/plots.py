"""Pictures (matplotlib, Agg): projected scans, trajectories against GPS, lines with 95 % bands."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from features.geometry import FloatArray  # noqa: E402
from slam.trajectory import Trajectory  # noqa: E402

__all__ = ["plot_scans", "plot_trajectories", "plot_lines"]

_COLOURS = {"gps": "k", "dr": "tab:red", "ekf": "tab:blue", "isam2": "tab:green", "truth": "k"}


def _draw_points(ax: plt.Axes, points_w: FloatArray, cell_m: float = 0.25) -> None:
    """Projected bins as a density image (log scale): walls are where many bins agree."""
    if points_w.shape[0] == 0:
        return
    lo = points_w.min(axis=0) - 1.0
    hi = points_w.max(axis=0) + 1.0
    bins = np.maximum(((hi - lo) / cell_m).astype(int), 1)
    h, xe, ye = np.histogram2d(
        points_w[:, 0], points_w[:, 1], bins=bins, range=[[lo[0], hi[0]], [lo[1], hi[1]]]
    )
    ax.imshow(
        np.log1p(h.T),
        origin="lower",
        extent=(xe[0], xe[-1], ye[0], ye[-1]),
        cmap="Greys",
        interpolation="nearest",
        vmax=max(np.log1p(h).max() * 0.8, 1e-9),
    )


def plot_scans(
    path: str | Path,
    points_w: FloatArray,
    trajectories: dict[str, Trajectory],
    title: str,
    segments_w: Sequence[FloatArray] = (),
) -> Path:
    """Projected sonar bins (grey), trajectories and optional segments (rows of 2 points)."""
    fig, ax = plt.subplots(figsize=(9, 9), dpi=130)
    _draw_points(ax, points_w)
    for seg in segments_w:
        ax.plot(seg[:, 0], seg[:, 1], "m-", lw=1.2)
    for name, tr in trajectories.items():
        ax.plot(
            tr.poses_wTb[:, 0],
            tr.poses_wTb[:, 1],
            "-",
            lw=1.0,
            color=_COLOURS.get(name),
            label=name,
        )
    ax.set_aspect("equal")
    ax.set_xlabel("East (m)")
    ax.set_ylabel("North (m)")
    ax.set_title(title)
    if trajectories:
        ax.legend(loc="best")
    ax.grid(True, lw=0.3)
    out = Path(path)
    fig.tight_layout()
    fig.savefig(out)
    plt.close(fig)
    return out


def plot_trajectories(
    path: str | Path,
    trajectories: dict[str, Trajectory],
    errors: dict[str, tuple[FloatArray, FloatArray]],
    title: str,
) -> Path:
    """Trajectories in the plane (left) and their ATE against time (right)."""
    fig, (ax, ax2) = plt.subplots(1, 2, figsize=(14, 6.5), dpi=110)
    for name, tr in trajectories.items():
        ax.plot(
            tr.poses_wTb[:, 0],
            tr.poses_wTb[:, 1],
            "-",
            lw=1.0,
            color=_COLOURS.get(name),
            label=name,
        )
    ax.set_aspect("equal")
    ax.set_xlabel("East (m)")
    ax.set_ylabel("North (m)")
    ax.legend()
    ax.grid(True, lw=0.3)
    for name, (t, e) in errors.items():
        ax2.plot(
            t - t[0], e, lw=1.0, color=_COLOURS.get(name), label=f"{name}: mean {e.mean():.2f} m"
        )
    ax2.set_xlabel("time (s)")
    ax2.set_ylabel("position error against GPS (m)")
    ax2.legend()
    ax2.grid(True, lw=0.3)
    fig.suptitle(title)
    fig.tight_layout()
    out = Path(path)
    fig.savefig(out)
    plt.close(fig)
    return out


def _densest_window(points_w: FloatArray, side_m: float) -> tuple[float, float]:
    """Centre of the ``side_m`` square (on a grid of half steps) holding most of ``points_w``."""
    lo = points_w.min(axis=0)
    cells = np.floor((points_w - lo) / (0.5 * side_m)).astype(np.int64)
    keys, counts = np.unique(cells, axis=0, return_counts=True)
    # a window is 2 x 2 half cells: sum the counts of each 2 x 2 block
    table = {tuple(k): int(c) for k, c in zip(keys, counts, strict=True)}
    best, best_n = keys[0], -1
    for k in keys:
        n = sum(table.get((int(k[0]) + a, int(k[1]) + b), 0) for a in (0, 1) for b in (0, 1))
        if n > best_n:
            best, best_n = k, n
    centre = lo + (best + 1.0) * 0.5 * side_m
    return float(centre[0]), float(centre[1])


def _draw_lines(
    ax: plt.Axes,
    segments_w: Sequence[FloatArray],
    bands_w: Sequence[FloatArray],
    lw: float,
) -> None:
    for band in bands_w:
        ax.fill(band[:, 0], band[:, 1], fc="tab:orange", ec="darkorange", alpha=0.45, lw=0.3)
    for k, seg in enumerate(segments_w):
        ax.plot(
            seg[:, 0],
            seg[:, 1],
            "-",
            color="tab:red",
            lw=lw,
            label="line segment, 95 % band in orange" if k == 0 else None,
        )


def plot_lines(
    path: str | Path,
    points_w: FloatArray,
    segments_w: Sequence[FloatArray],
    bands_w: Sequence[FloatArray],
    title: str,
    trajectories: dict[str, Trajectory] | None = None,
    zoom_side_m: float | None = None,
) -> Path:
    """Line segments with their confidence bands over the density image of projected bins.

    The left panel shows everything; the right one zooms on the square of side ``zoom_side_m``
    (default: an eighth of the larger extent of the points) holding most segment midpoints, where
    the bands are wide enough to see.

    Parameters
    ----------
    path : str or Path
        PNG file.
    points_w : ndarray, shape (N, 2)
        Projected bins, world East-North (m).
    segments_w : sequence of ndarray, shape (2, 2)
        Segment ends, world (m).
    bands_w : sequence of ndarray, shape (M, 2)
        Band polygons, world (m), e.g. :func:`slam.extraction.segment_band_world`.
    title : str
    trajectories : dict of str to Trajectory, optional
        Drawn thin, under the lines.
    zoom_side_m : float, optional
        Side of the zoomed square (m).
    """
    fig, axes = plt.subplots(1, 2, figsize=(16, 9), dpi=90)
    for ax, lw in zip(axes, (0.6, 1.0), strict=True):
        _draw_points(ax, points_w)
        for name, tr in (trajectories or {}).items():
            ax.plot(
                tr.poses_wTb[:, 0],
                tr.poses_wTb[:, 1],
                "-",
                lw=0.6,
                alpha=0.7,
                color="tab:blue",
                label=f"{name} trajectory",
            )
        _draw_lines(ax, segments_w, bands_w, lw)
        ax.set_aspect("equal")
        ax.set_xlabel("East (m)")
        ax.set_ylabel("North (m)")
        ax.grid(True, lw=0.3)
    axes[0].set_title(title)
    if segments_w or trajectories:
        axes[0].legend(loc="best", fontsize="small")
    if segments_w:
        mids = np.array([0.5 * (seg[0] + seg[1]) for seg in segments_w])
        ext = np.ptp(points_w, axis=0).max() if points_w.shape[0] else np.ptp(mids, axis=0).max()
        side = zoom_side_m if zoom_side_m is not None else max(float(ext) / 8.0, 1.0)
        cx, cy = _densest_window(mids, side)
        axes[1].set_xlim(cx - 0.5 * side, cx + 0.5 * side)
        axes[1].set_ylim(cy - 0.5 * side, cy + 0.5 * side)
        axes[1].set_title(f"zoom: {side:.0f} m x {side:.0f} m with the most segments")
        axes[0].add_patch(
            plt.Rectangle(
                (cx - 0.5 * side, cy - 0.5 * side), side, side, fill=False, ec="tab:blue", lw=0.8
            )
        )
    out = Path(path)
    fig.tight_layout()
    fig.savefig(out)
    plt.close(fig)
    return out
