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

__all__ = ["plot_scans", "plot_trajectories"]

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
