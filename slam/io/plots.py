"""Pictures (matplotlib, Agg): projected scans, trajectories against GPS, lines with 95 % bands."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from features.geometry import FloatArray  # noqa: E402
from slam.io.trajectory import Trajectory  # noqa: E402

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


def _draw_trajectories(ax: plt.Axes, trajectories: dict[str, Trajectory]) -> None:
    for name, tr in trajectories.items():
        ax.plot(
            tr.poses_wTb[:, 0],
            tr.poses_wTb[:, 1],
            "-",
            lw=1.0,
            color=_COLOURS.get(name),
            label=name,
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
    _draw_trajectories(ax, trajectories)
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
    _draw_trajectories(ax, trajectories)
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
        Band polygons, world (m), e.g. :func:`slam.run.extraction.segment_band_world`.
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


# -- evaluation pictures (slam.run.report, slam.run.sweep) ---------------------------------------------


def _chi2_band(dof: int, n_runs: int = 1, probability: float = 0.95) -> tuple[float, float]:
    from scipy.stats import chi2

    a = 0.5 * (1.0 - probability)
    lo, hi = chi2.ppf([a, 1.0 - a], n_runs * dof) / n_runs
    return float(lo), float(hi)


def plot_error_bounds(
    path: str | Path,
    t_s: FloatArray,
    errors: FloatArray,
    sigmas: FloatArray | None,
    title: str,
    reference: str = "GPS",
) -> Path:
    """Errors against time with their 3-sigma bounds: East, North (and heading when given).

    Parameters
    ----------
    path : str or Path
        PNG file.
    t_s : ndarray, shape (K,)
        Times (s); drawn from the first.
    errors : ndarray, shape (K, 2) or (K, 3)
        Estimate minus reference: East (m), North (m) and optionally heading (rad, wrapped).
    sigmas : ndarray, shape (K, 2) or (K, 3), or None
        One-sigma of each error (no bounds drawn when None).
    title : str
    reference : str
        Name of the reference in the labels.
    """
    n = errors.shape[1]
    names = ["East error (m)", "North error (m)", "heading error (deg)"][:n]
    scale = np.array([1.0, 1.0, np.rad2deg(1.0)])[:n]
    fig, axes = plt.subplots(n, 1, figsize=(11, 2.6 * n + 0.8), dpi=100, sharex=True)
    axes = np.atleast_1d(axes)
    t = t_s - t_s[0] if t_s.size else t_s
    for k, ax in enumerate(axes):
        e = errors[:, k] * scale[k]
        ax.plot(t, e, lw=0.8, color="tab:blue", label=f"estimate - {reference}")
        if sigmas is not None:
            b = 3.0 * sigmas[:, k] * scale[k]
            inside = float(np.mean(np.abs(e) <= b)) if e.size else float("nan")
            ax.fill_between(
                t,
                -b,
                b,
                color="tab:orange",
                alpha=0.3,
                lw=0,
                label=f"±3 sigma ({100 * inside:.1f} % inside)",
            )
        ax.axhline(0.0, color="k", lw=0.5)
        ax.set_ylabel(names[k])
        ax.grid(True, lw=0.3)
        ax.legend(loc="upper left", fontsize="small")
    axes[-1].set_xlabel("time (s)")
    axes[0].set_title(title)
    fig.tight_layout()
    out = Path(path)
    fig.savefig(out)
    plt.close(fig)
    return out


def plot_nees(
    path: str | Path,
    series: dict[str, tuple[FloatArray, FloatArray, int]],
    title: str,
    probability: float = 0.95,
) -> Path:
    """NEES against time, one panel per series, with the two-sided chi2(dof) band of one value.

    ``series`` maps a label to ``(t_s (K,), nees (K,), dof)``.
    """
    n = max(len(series), 1)
    fig, axes = plt.subplots(n, 1, figsize=(11, 2.8 * n + 0.8), dpi=100, sharex=True)
    axes = np.atleast_1d(axes)
    for ax, (label, (t, v, dof)) in zip(axes, series.items(), strict=False):
        lo, hi = _chi2_band(dof, 1, probability)
        tt = t - t[0] if t.size else t
        inside = float(np.mean((v >= lo) & (v <= hi))) if v.size else float("nan")
        ax.semilogy(
            tt,
            np.maximum(v, 1e-6),
            lw=0.7,
            color="tab:blue",
            label=f"{label}: mean {np.mean(v):.2f}",
        )
        ax.axhspan(
            lo,
            hi,
            color="tab:green",
            alpha=0.15,
            label=f"{100 * probability:.0f} % band of chi2({dof}): {100 * inside:.1f} % inside",
        )
        ax.axhline(dof, color="tab:green", lw=0.8)
        ax.set_ylabel(f"NEES ({dof} dof)")
        ax.grid(True, which="both", lw=0.3)
        ax.legend(loc="upper left", fontsize="small")
    axes[-1].set_xlabel("time (s)")
    axes[0].set_title(title)
    fig.tight_layout()
    out = Path(path)
    fig.savefig(out)
    plt.close(fig)
    return out


def plot_anees(path: str | Path, curves: dict[str, object], title: str) -> Path:
    """ANEES against time with the band of its number of runs, one curve per configuration.

    ``curves`` maps a label to a :class:`slam.eval.consistency.AneesResult`.
    """
    fig, ax = plt.subplots(figsize=(11, 5), dpi=100)
    colours = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    for k, (label, res) in enumerate(curves.items()):
        c = colours[k % len(colours)]
        t = res.t_rel_s  # type: ignore[attr-defined]
        ax.semilogy(
            t,
            res.anees,
            lw=0.9,
            color=c,
            label=f"{label}: ANEES {res.mean:.2f}, {100 * res.in_band_fraction:.0f} % of times in band",
        )  # type: ignore[attr-defined]
        ax.fill_between(t, res.band_lo, res.band_hi, color=c, alpha=0.12, lw=0)  # type: ignore[attr-defined]
    if curves:
        dof = next(iter(curves.values())).dof  # type: ignore[attr-defined]
        ax.axhline(dof, color="k", lw=0.6, ls="--", label=f"dof = {dof}")
    ax.set_xlabel("time since start (s)")
    ax.set_ylabel("ANEES (mean NEES over the runs)")
    ax.set_title(title + "\n(shaded: two-sided 95 % band of the mean of N chi2)")
    ax.grid(True, which="both", lw=0.3)
    ax.legend(loc="best", fontsize="small")
    fig.tight_layout()
    out = Path(path)
    fig.savefig(out)
    plt.close(fig)
    return out


def plot_sweep(path: str | Path, table: object, labels: FloatArray, title: str) -> Path:
    """Per configuration: the ATE mean of each run, its pose NEES mean (log), its wall time.

    ``table`` is the sweep's DataFrame; ``labels`` (R,) names each row's configuration.
    """
    import pandas as pd

    assert isinstance(table, pd.DataFrame)
    ok = (
        (table["error"].fillna("") == "").to_numpy()
        if "error" in table
        else np.ones(len(table), bool)
    )
    names = list(dict.fromkeys(labels))
    panels = [
        ("ate_mean_m", "ATE mean against GPS (m)", False),
        ("nees_mean", "pose NEES mean over time (3 dof)", True),
        ("wall_s", "wall time (s)", False),
    ]
    fig, axes = plt.subplots(1, len(panels), figsize=(5 * len(panels), 5), dpi=100)
    rng = np.random.default_rng(0)  # jitter of the dots only
    for ax, (col, ylabel, log) in zip(axes, panels, strict=True):
        data = []
        for name in names:
            sel = (labels == name) & ok
            v = table.loc[sel, col].to_numpy(dtype=float) if col in table else np.zeros(0)
            data.append(v[np.isfinite(v)])
        ax.boxplot([d if d.size else [np.nan] for d in data], showfliers=False)
        for i, d in enumerate(data):
            ax.plot(i + 1 + rng.uniform(-0.15, 0.15, d.size), d, ".", ms=4, alpha=0.6)
        if col == "nees_mean":
            ax.axhline(3.0, color="tab:green", lw=0.8, label="dof = 3")
            ax.legend(fontsize="small")
        if log:
            ax.set_yscale("log")
        ax.set_xticks(range(1, len(names) + 1), names, rotation=20, ha="right", fontsize="small")
        ax.set_ylabel(ylabel)
        ax.grid(True, which="both", lw=0.3)
    fig.suptitle(title)
    fig.tight_layout()
    out = Path(path)
    fig.savefig(out)
    plt.close(fig)
    return out


__all__ += ["plot_error_bounds", "plot_nees", "plot_anees", "plot_sweep"]
