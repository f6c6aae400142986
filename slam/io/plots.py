"""Evaluation pictures: trajectories and their ATE against the reference, the ATE per time
segment, errors with their bounds, NEES, ANEES and the sweep (maps: :mod:`sonarslam.slam.io.maps`).

Matplotlib's object interface (``Figure``), so that importing this module changes no global
state (no backend switch, no pyplot figure registry): every function draws into its own figure
and writes a PNG.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any, Protocol

import matplotlib
import numpy as np
import numpy.typing as npt
import pandas as pd
from matplotlib.axes import Axes
from matplotlib.figure import Figure
from matplotlib.ticker import FuncFormatter

from sonarslam.features.geometry import FloatArray
from sonarslam.slam.io.maps import MapLayers, data_box, draw_map, trajectory_style
from sonarslam.slam.io.trajectory import Trajectory

__all__ = [
    "ate_legend",
    "plot_trajectories",
    "plot_segment_ate",
    "plot_error_bounds",
    "plot_nees",
    "AneesCurve",
    "plot_anees",
    "plot_sweep",
    "plot_worlds",
    "plot_learned_noise",
]


def _plain_log_label(value: float, _pos: float) -> str:
    return f"{value:g}"


def _plain_minor_label(value: float, _pos: float) -> str:
    """Label the 2 and 5 of each decade only: 0.2, 0.5, 2, 5, 20, ..."""
    if value <= 0:
        return ""
    mantissa = value / 10.0 ** np.floor(np.log10(value))
    return (
        f"{value:g}" if round(mantissa) in (2, 5) and abs(mantissa - round(mantissa)) < 1e-6 else ""
    )


def _plain_log_axis(ax: Axes) -> None:
    """Plain numbers on a log y axis (0.5, 1, 2, 5, 10), not 2x10^0."""
    ax.yaxis.set_major_formatter(FuncFormatter(_plain_log_label))
    ax.yaxis.set_minor_formatter(FuncFormatter(_plain_minor_label))


def _time_axis(
    ax: Axes, t0_s: float, sonar_span_s: tuple[float, float] | None, t1_s: float
) -> None:
    """Shade the times outside the sonar span (every method is dead reckoning there)."""
    if sonar_span_s is None:
        return
    a, b = sonar_span_s[0] - t0_s, sonar_span_s[1] - t0_s
    label: str | None = "no sonar (dead reckoning only)"
    if a > 0:
        ax.axvspan(0.0, a, color="0.5", alpha=0.15, lw=0, label=label)
        label = None
    if b < t1_s - t0_s:
        ax.axvspan(b, t1_s - t0_s, color="0.5", alpha=0.15, lw=0, label=label)


def ate_legend(
    label: str,
    t_s: FloatArray,
    errors_m: FloatArray,
    sonar_span_s: tuple[float, float] | None = None,
) -> str:
    """An estimate's legend entry: its ATE (mean and max of the position errors ``errors_m`` at
    the times ``t_s``, Unix s) over the sonar span (the errors inside ``sonar_span_s``, as
    ``metrics.json``'s ``ate_sonar_*``) when one is given and holds errors, and over the whole
    run (``ate_*``), each span named (one figure when the sonar span holds every error)."""
    whole = f"whole run mean {errors_m.mean():.2f} m, max {errors_m.max():.2f} m"
    if sonar_span_s is None:
        return f"{label}: {whole}"
    inside = (t_s >= sonar_span_s[0]) & (t_s <= sonar_span_s[1])
    if not inside.any():
        return f"{label}: {whole}"
    if inside.all():
        return f"{label}: {whole} (all of it in the sonar span)"
    e = errors_m[inside]
    return f"{label}: sonar span mean {e.mean():.2f} m, max {e.max():.2f} m; {whole}"


def plot_trajectories(
    path: str | Path,
    trajectories: dict[str, Trajectory],
    errors: dict[str, tuple[FloatArray, FloatArray]],
    title: str,
    reference: str = "GPS",
    sonar_span_s: tuple[float, float] | None = None,
    walls_w: FloatArray | None = None,
) -> Path:
    """Trajectories in the plane (left, cropped to them; the true walls of a simulated run) and
    their position error against ``reference`` in time (right), the times outside the sonar span
    shaded; one legend below both, each estimate with its ATE over the sonar span and the whole
    run (:func:`ate_legend`).

    ``trajectories`` holds the reference (``"gps"`` or ``"truth"``) and the estimates by name,
    drawn in :func:`sonarslam.slam.io.maps.trajectory_style`; ``errors`` maps an estimate's
    name to its times (Unix s) and errors (m). Without errors (a run with neither GPS nor
    truth) the plane alone is drawn.
    """
    layers = MapLayers(np.zeros((0, 2)), trajectories, walls_w=walls_w)
    if not errors:
        fig = Figure(figsize=(8, 7.2), dpi=110, layout="constrained")
        ax = fig.subplots()
        draw_map(ax, layers, data_box(layers))
        fig.legend(loc="outside lower center", ncols=2, fontsize="small")
        fig.suptitle(title)
        out = Path(path)
        fig.savefig(out, bbox_inches="tight")
        return out
    fig = Figure(figsize=(13, 7.2), dpi=110, layout="constrained")
    (ax, ax2) = fig.subplots(1, 2, width_ratios=[1.0, 1.3])
    draw_map(ax, layers, data_box(layers))
    t0 = min((float(t[0]) for t, _ in errors.values() if t.size), default=0.0)
    t1 = max((float(t[-1]) for t, _ in errors.values() if t.size), default=t0)
    _time_axis(ax2, t0, sonar_span_s, t1)
    order = {"dr": 0}
    for name in sorted(errors, key=lambda n: order.get(n, 1)):
        t, e = errors[name]
        style = trajectory_style(name)
        ax2.plot(
            t - t0,
            e,
            lw=1.0,
            ls=style.linestyle,
            color=style.colour,
            label=ate_legend(style.label, t, e, sonar_span_s),
        )
    ax2.set_xlabel("time since the start (s)")
    ax2.set_ylabel(f"position error against {reference} (m)")
    ax2.set_ylim(bottom=0.0)
    ax2.grid(True, lw=0.3)
    # the references and walls from the plane, the estimates with their figures from the errors
    estimates = {trajectory_style(n).label for n in errors}
    left = [(h, lab) for h, lab in zip(*ax.get_legend_handles_labels(), strict=True)]
    handles = [(h, lab) for h, lab in left if lab not in estimates]
    handles += list(zip(*ax2.get_legend_handles_labels(), strict=True))
    fig.legend(*zip(*handles, strict=True), loc="outside lower center", ncols=2, fontsize="small")
    fig.suptitle(title)
    out = Path(path)
    fig.savefig(out, bbox_inches="tight")
    return out


def plot_segment_ate(
    path: str | Path,
    edges_s: FloatArray,
    stats: dict[str, tuple[FloatArray, FloatArray]],
    title: str,
    reference: str = "GPS",
    sonar_end_s: float | None = None,
) -> Path:
    """The ATE per time segment: one bar per method (its mean), a dot for its max.

    Parameters
    ----------
    edges_s : ndarray, shape (K + 1,)
        Segment edges, seconds since the start.
    stats : dict of str to (ndarray (K,), ndarray (K,))
        A method's name (:func:`sonarslam.slam.io.maps.trajectory_style`) to the mean and max error (m)
        of each segment (NaN: no fix there).
    sonar_end_s : float, optional
        When the sonar stops, seconds since the start (a dashed line).
    """
    k = edges_s.size - 1
    fig = Figure(figsize=(max(7.0, 0.9 * k + 3.0), 4.8), dpi=110, layout="constrained")
    ax = fig.subplots()
    width = 0.8 / max(len(stats), 1)
    x = np.arange(k)
    for i, (name, (mean, peak)) in enumerate(stats.items()):
        style = trajectory_style(name)
        xs = x - 0.4 + (i + 0.5) * width
        ax.bar(xs, mean, width * 0.9, color=style.colour, alpha=0.8, label=f"{style.label}: mean")
        ax.plot(xs, peak, "_", color=style.colour, ms=10, mew=2)
    ax.plot([], [], "_", color="k", ms=10, mew=2, label="max of the segment")
    if sonar_end_s is not None and sonar_end_s < edges_s[-1]:
        pos = float(np.interp(sonar_end_s, edges_s, np.arange(k + 1) - 0.5))
        ax.axvline(pos, color="0.3", ls="--", lw=1.0, label="the sonar stops")
    ax.set_xticks(x, [f"{a:.0f}-{b:.0f}" for a, b in zip(edges_s[:-1], edges_s[1:], strict=True)])
    ax.set_xlabel("time since the start (s)")
    ax.set_ylabel(f"position error against {reference} (m)")
    ax.grid(True, axis="y", lw=0.3)
    fig.legend(loc="outside right upper", fontsize="small")
    ax.set_title(title, fontsize="medium")
    out = Path(path)
    fig.savefig(out, bbox_inches="tight")
    return out


# -- evaluation pictures (slam.run.report, slam.run.sweep) ---------------------------------------------


def plot_error_bounds(
    path: str | Path,
    t_s: FloatArray,
    errors: FloatArray,
    sigmas: FloatArray | None,
    title: str,
    reference: str = "GPS",
    band_label: str = "±3 sigma",
    aligned: FloatArray | None = None,
) -> Path:
    """Errors against time with their 3-sigma bounds: East, North (and heading when given);
    and, when given, the error after a rigid alignment (no band), the same for every run.

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
    band_label : str
        What the band is (which covariance model): its legend entry.
    aligned : ndarray, shape (K, 2), optional
        East and North error (m) after a rigid alignment of the estimate onto the reference.
    """
    n = errors.shape[1]
    names = ["East error (m)", "North error (m)", "heading error (deg)"][:n]
    scale = np.array([1.0, 1.0, np.rad2deg(1.0)])[:n]
    fig = Figure(figsize=(12, 2.6 * n + 0.8), dpi=100, layout="constrained")
    axes = fig.subplots(n, 1, sharex=True, squeeze=False)[:, 0]
    t = t_s - t_s[0] if t_s.size else t_s
    for k, ax in enumerate(axes):
        e = errors[:, k] * scale[k]
        ax.plot(t, e, lw=0.8, color="tab:blue", label=f"estimate - {reference}")
        if aligned is not None and k < aligned.shape[1]:
            ax.plot(t, aligned[:, k], lw=0.8, color="tab:purple", label="after a rigid alignment")
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
                label=f"{band_label} ({100 * inside:.1f} % inside)",
            )
        ax.axhline(0.0, color="k", lw=0.5)
        ax.set_ylabel(names[k])
        ax.grid(True, lw=0.3)
        ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize="small")
    axes[-1].set_xlabel("time (s)")
    axes[0].set_title(title)
    out = Path(path)
    fig.savefig(out, bbox_inches="tight")
    return out


def plot_nees(
    path: str | Path,
    series: dict[str, tuple[FloatArray, FloatArray, int, tuple[float, float]]],
    title: str,
    probability: float = 0.95,
) -> Path:
    """NEES against time, one panel per series, with the two-sided chi2(dof) band of one value.

    ``series`` maps a label to ``(t_s (K,), nees (K,), dof, (lo, hi))``, the band of
    ``probability`` (:func:`sonarslam.slam.eval.consistency.chi2_band`).
    """
    n = max(len(series), 1)
    fig = Figure(figsize=(12, 2.8 * n + 0.8), dpi=100, layout="constrained")
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
        _plain_log_axis(ax)
        ax.set_ylabel(f"NEES ({dof} dof)")
        ax.grid(True, which="both", lw=0.3)
        ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize="small")
    axes[-1].set_xlabel("time (s)")
    axes[0].set_title(title)
    out = Path(path)
    fig.savefig(out, bbox_inches="tight")
    return out


class AneesCurve(Protocol):
    """What :func:`plot_anees` draws of an ANEES (:class:`sonarslam.slam.eval.consistency.AneesResult`)."""

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
    fig = Figure(figsize=(12, 5), dpi=100, layout="constrained")
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
    _plain_log_axis(ax)
    ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize="small")
    out = Path(path)
    fig.savefig(out, bbox_inches="tight")
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
    :func:`sonarslam.slam.run.sweep_summary.pair_with_baseline`); ``labels`` (R,) names each row's
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
        ("ate_truth_mean_m", "ATE mean against the truth (m)", False)
        if "ate_truth_mean_m" in table
        else ("ate_mean_m", "ATE mean against GPS (m)", False),
        ("ate_truth_aligned_mean_m", "ATE mean after rigid alignment (m)", False),
        ("gain_over_dr", "gain over DR, same seed (1 - ATE / ATE_DR)", False),
        ("nees_mean", "pose NEES mean over time (3 dof)", True),
        ("nees_position_mean", "position NEES mean over time (2 dof)", True),
        ("wall_s", "wall time (s)", False),
    ]
    panels = [p for p in panels if p[0] in table]
    n_cols = min(3, len(panels))
    n_rows = -(-len(panels) // n_cols)
    fig = Figure(figsize=(5 * n_cols, 5 * n_rows), dpi=100, layout="constrained")
    axes = np.atleast_1d(fig.subplots(n_rows, n_cols)).ravel()
    for ax in axes[len(panels) :]:
        ax.set_visible(False)
    rng = np.random.default_rng(0)  # jitter of the dots only
    for ax, (col, ylabel, log) in zip(axes, panels, strict=False):
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
            _plain_log_axis(ax)
        ax.set_xticks(range(1, len(names) + 1), ticks, rotation=20, ha="right", fontsize="small")
        ax.set_ylabel(ylabel)
        ax.grid(True, which="both", lw=0.3)
    fig.suptitle(title)
    out = Path(path)
    fig.savefig(out, bbox_inches="tight")
    return out


def plot_worlds(
    path: str | Path,
    worlds: list[tuple[str, FloatArray, npt.NDArray[Any] | None, FloatArray]],
    title: str,
) -> Path:
    """Simulated worlds side by side: each one's walls (curved stretches in red) and the true
    route of its vehicle.

    Parameters
    ----------
    path : str or Path
        The picture.
    worlds : list of (title, walls, curve, route)
        ``walls`` (W, 2, 2) wall segments (m), ``curve`` (W,) the curved stretch of each wall
        (-1: straight; None: all straight), ``route`` (P, 2) the true positions (m), its start
        marked.
    title : str
    """
    n = max(len(worlds), 1)
    n_cols = min(3, n)
    n_rows = -(-n // n_cols)
    fig = Figure(figsize=(5.5 * n_cols, 5 * n_rows), dpi=100, layout="constrained")
    axes = np.atleast_1d(fig.subplots(n_rows, n_cols)).ravel()
    for ax in axes[len(worlds) :]:
        ax.set_visible(False)
    for ax, (name, walls, curve, route) in zip(axes, worlds, strict=False):
        curved = np.zeros(walls.shape[0], bool) if curve is None else np.asarray(curve) >= 0
        for mask, colour, label in ((~curved, "black", "walls"), (curved, "tab:red", "curved")):
            if mask.any():
                segs = walls[mask]
                xs = np.column_stack([segs[:, 0, 0], segs[:, 1, 0], np.full(len(segs), np.nan)])
                ys = np.column_stack([segs[:, 0, 1], segs[:, 1, 1], np.full(len(segs), np.nan)])
                ax.plot(xs.ravel(), ys.ravel(), color=colour, lw=1.0, label=label)
        ax.plot(route[:, 0], route[:, 1], color="tab:blue", lw=0.6, label="route (truth)")
        ax.plot(route[0, 0], route[0, 1], "o", color="tab:green", ms=5, label="start")
        ax.set_aspect("equal")
        ax.set_title(name, fontsize="medium")
        ax.set_xlabel("East (m)")
        ax.set_ylabel("North (m)")
        ax.grid(True, lw=0.3)
    if worlds:
        axes[0].legend(fontsize="small", loc="best")
    fig.suptitle(title)
    out = Path(path)
    fig.savefig(out, bbox_inches="tight")
    return out


def plot_heading_error(
    path: str | Path,
    t_s: FloatArray,
    b_deg: FloatArray,
    sd_deg: FloatArray,
    title: str,
    truth: tuple[FloatArray, FloatArray] | None = None,
) -> Path:
    """The AHRS heading error's track in time with its 2-sigma band (and the true error of a
    simulated run, ``(t_s, b_deg)``, with the share of it inside the band).

    Parameters
    ----------
    t_s, b_deg, sd_deg : ndarray, shape (N,)
        Unix s, the estimate and its sd (deg).
    """
    fig = Figure(figsize=(12, 3.6), dpi=100, layout="constrained")
    ax = fig.subplots()
    t0 = float(t_s[0]) if t_s.size else 0.0
    tt = t_s - t0
    ax.fill_between(
        tt, b_deg - 2 * sd_deg, b_deg + 2 * sd_deg, color="tab:blue", alpha=0.2, label="±2σ"
    )
    ax.plot(tt, b_deg, color="tab:blue", lw=1.0, label="estimate")
    if truth is not None and t_s.size:
        t_true, b_true = truth
        at = np.interp(t_s, t_true, b_true)
        inside = float(np.mean(np.abs(at - b_deg) <= 2 * sd_deg))
        ax.plot(
            t_true - t0,
            b_true,
            color="black",
            lw=0.8,
            label=f"truth ({100 * inside:.0f} % of the nodes inside ±2σ)",
        )
    ax.set_xlabel("time (s)")
    ax.set_ylabel("heading error b (deg)")
    ax.grid(True, lw=0.3)
    ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize="small")
    ax.set_title(title)
    out = Path(path)
    fig.savefig(out, bbox_inches="tight")
    return out


#: The learned noise's panels: column of ``noise.csv`` (:data:`sonarslam.slam.io.states.NOISE_COLUMNS`
#: order) -> its axis label.
_NOISE_LABELS = (
    "heading walk (deg/√s)",
    "DVL scale walk (1/√s)",
    "line covariance ×",
    "revisit covariance ×",
)


def plot_learned_noise(path: str | Path, t_s: FloatArray, values: FloatArray, title: str) -> Path:
    """The noise a loop learned over time: one step panel per learned column (NaN columns are
    not learned and left out).

    Parameters
    ----------
    t_s : ndarray, shape (N,)
        Unix s of the start and each step.
    values : ndarray, shape (N, 4)
        ``noise.csv``'s columns (:func:`sonarslam.slam.io.states.read_learned_noise`).
    """
    cols = [c for c in range(values.shape[1]) if np.any(np.isfinite(values[:, c]))]
    fig = Figure(figsize=(12, 1.0 + 1.6 * max(len(cols), 1)), dpi=100, layout="constrained")
    axes = np.atleast_1d(fig.subplots(max(len(cols), 1), 1, sharex=True))
    tt = t_s - (float(t_s[0]) if t_s.size else 0.0)
    for ax, c in zip(axes, cols, strict=False):
        ax.step(tt, values[:, c], where="post", color="tab:blue", lw=1.0)
        ax.set_ylabel(_NOISE_LABELS[c], fontsize="small")
        ax.grid(True, lw=0.3)
    axes[-1].set_xlabel("time (s)")
    axes[0].set_title(title)
    out = Path(path)
    fig.savefig(out, bbox_inches="tight")
    return out
