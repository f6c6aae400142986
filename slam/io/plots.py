"""Pictures: projected scans, trajectories against GPS, lines with 95 % bands, errors and NEES.

Matplotlib's object interface (``Figure``), so that importing this module changes no global
state (no backend switch, no pyplot figure registry): every function draws into its own figure
and writes a PNG.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any, Protocol

import matplotlib
import numpy as np
import numpy.typing as npt
import pandas as pd
from matplotlib.axes import Axes
from matplotlib.figure import Figure
from matplotlib.patches import Rectangle
from scipy.stats import chi2

from features.geometry import FloatArray, transform_points
from features.line import LineFeature
from slam.io.trajectory import Trajectory

__all__ = [
    "plot_scans",
    "plot_trajectories",
    "plot_lines",
    "segment_band_world",
    "plot_error_bounds",
    "plot_nees",
    "AneesCurve",
    "plot_anees",
    "plot_sweep",
]

_COLOURS = {"gps": "k", "dr": "tab:red", "ekf": "tab:blue", "isam2": "tab:green", "truth": "k"}


def _draw_points(ax: Axes, points_w: FloatArray, cell_m: float = 0.25) -> None:
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


def _draw_trajectories(ax: Axes, trajectories: dict[str, Trajectory]) -> None:
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
    fig = Figure(figsize=(9, 9), dpi=130)
    ax = fig.subplots()
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
    return out


def plot_trajectories(
    path: str | Path,
    trajectories: dict[str, Trajectory],
    errors: dict[str, tuple[FloatArray, FloatArray]],
    title: str,
) -> Path:
    """Trajectories in the plane (left) and their ATE against time (right)."""
    fig = Figure(figsize=(14, 6.5), dpi=110)
    (ax, ax2) = fig.subplots(1, 2)
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
    ax: Axes,
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
    fig = Figure(figsize=(16, 9), dpi=90)
    axes = fig.subplots(1, 2)
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
            Rectangle(
                (cx - 0.5 * side, cy - 0.5 * side), side, side, fill=False, ec="tab:blue", lw=0.8
            )
        )
    out = Path(path)
    fig.tight_layout()
    fig.savefig(out)
    return out


# -- evaluation pictures (slam.run.report, slam.run.sweep) ---------------------------------------------


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
    fig = Figure(figsize=(11, 2.6 * n + 0.8), dpi=100)
    axes = fig.subplots(n, 1, sharex=True, squeeze=False)[:, 0]
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
    return out


def plot_nees(
    path: str | Path,
    series: dict[str, tuple[FloatArray, FloatArray, int, tuple[float, float]]],
    title: str,
    probability: float = 0.95,
) -> Path:
    """NEES against time, one panel per series, with the two-sided chi2(dof) band of one value.

    ``series`` maps a label to ``(t_s (K,), nees (K,), dof, (lo, hi))``, the band of
    ``probability`` (:func:`slam.eval.consistency.chi2_band`).
    """
    n = max(len(series), 1)
    fig = Figure(figsize=(11, 2.8 * n + 0.8), dpi=100)
    axes = fig.subplots(n, 1, sharex=True, squeeze=False)[:, 0]
    for ax, (label, (t, v, dof, (lo, hi))) in zip(axes, series.items(), strict=False):
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
    return out


class AneesCurve(Protocol):
    """What :func:`plot_anees` draws of an ANEES (:class:`slam.eval.consistency.AneesResult`)."""

    @property
    def t_rel_s(self) -> FloatArray: ...

    @property
    def anees(self) -> FloatArray: ...

    @property
    def band_lo(self) -> FloatArray: ...

    @property
    def band_hi(self) -> FloatArray: ...

    @property
    def dof(self) -> int: ...

    @property
    def mean(self) -> float: ...

    @property
    def in_band_fraction(self) -> float: ...


def plot_anees(path: str | Path, curves: Mapping[str, AneesCurve], title: str) -> Path:
    """ANEES against time with the band of its number of runs, one curve per configuration."""
    fig = Figure(figsize=(11, 5), dpi=100)
    ax = fig.subplots()
    colours = matplotlib.rcParams["axes.prop_cycle"].by_key()["color"]
    for k, (label, res) in enumerate(curves.items()):
        c = colours[k % len(colours)]
        t = res.t_rel_s
        ax.semilogy(
            t,
            res.anees,
            lw=0.9,
            color=c,
            label=f"{label}: ANEES {res.mean:.2f}, {100 * res.in_band_fraction:.0f} % of times in band",
        )
        ax.fill_between(t, res.band_lo, res.band_hi, color=c, alpha=0.12, lw=0)
    if curves:
        dof = next(iter(curves.values())).dof
        ax.axhline(dof, color="k", lw=0.6, ls="--", label=f"dof = {dof}")
    ax.set_xlabel("time since start (s)")
    ax.set_ylabel("ANEES (mean NEES over the runs)")
    ax.set_title(title + "\n(shaded: two-sided 95 % band of the mean of N chi2)")
    ax.grid(True, which="both", lw=0.3)
    ax.legend(loc="best", fontsize="small")
    fig.tight_layout()
    out = Path(path)
    fig.savefig(out)
    return out


def plot_sweep(
    path: str | Path,
    table: pd.DataFrame,
    labels: npt.NDArray[Any],
    title: str,
    notes: Mapping[str, str] | None = None,
) -> Path:
    """Per configuration, one dot per run: its ATE against the truth, as it is and rigidly
    aligned, its gain over dead reckoning on the same seed (``1 - ATE / ATE_dr``), its pose and
    position NEES means (log) and its wall time.

    ``table`` is the sweep's DataFrame (``gain_over_dr`` from
    :func:`slam.run.sweep_summary.pair_with_baseline`); ``labels`` (R,) names each row's
    configuration; ``notes`` maps a configuration to a line under its name in the gain panel
    (the share of seeds on which it beats dead reckoning).
    """
    ok = (
        (table["error"].fillna("") == "").to_numpy()
        if "error" in table
        else np.ones(len(table), bool)
    )
    names = list(dict.fromkeys(labels))
    panels = [
        ("ate_truth_mean_m", "ATE mean against the truth (m)", False),
        ("ate_truth_aligned_mean_m", "ATE mean after rigid alignment (m)", False),
        ("gain_over_dr", "gain over DR, same seed (1 - ATE / ATE_DR)", False),
        ("nees_mean", "pose NEES mean over time (3 dof)", True),
        ("nees_position_mean", "position NEES mean over time (2 dof)", True),
        ("wall_s", "wall time (s)", False),
    ]
    fig = Figure(figsize=(15, 10), dpi=100)
    axes = fig.subplots(2, 3).ravel()
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
        if col in ("nees_mean", "nees_position_mean"):
            dof = 3.0 if col == "nees_mean" else 2.0
            ax.axhline(dof, color="tab:green", lw=0.8, label=f"dof = {dof:g}")
            ax.legend(fontsize="small")
        ticks = names
        if col == "gain_over_dr":
            ax.axhline(0.0, color="tab:red", lw=0.8)
            ticks = [f"{n}\n{(notes or {}).get(n, '')}" for n in names]
        if log:
            ax.set_yscale("log")
        ax.set_xticks(range(1, len(names) + 1), ticks, rotation=20, ha="right", fontsize="small")
        ax.set_ylabel(ylabel)
        ax.grid(True, which="both", lw=0.3)
    fig.suptitle(title)
    fig.tight_layout()
    out = Path(path)
    fig.savefig(out)
    return out
