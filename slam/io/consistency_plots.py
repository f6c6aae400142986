"""The picture of one run's consistency in time (``consistency.png`` of a run directory): NEES
and NIS, each value with the two-sided chi2 band of one value, the medians over windows and
the health monitor's limit for them.

Matplotlib's object interface (``Figure``), as :mod:`sonarslam.slam.io.plots`.
"""

from __future__ import annotations

import textwrap
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from matplotlib.figure import Figure
from matplotlib.ticker import FuncFormatter

from sonarslam.features.geometry import FloatArray

__all__ = ["ConsistencyPanel", "plot_consistency"]


@dataclass(frozen=True)
class ConsistencyPanel:
    """One panel: values in time with their band, window medians and the limit on them.

    Attributes
    ----------
    label : str
        What the values are (``"pose NEES against the truth"``).
    t_s : ndarray, shape (K,)
        Unix times (s).
    values : ndarray, shape (K,)
    dof : int
    band : tuple of float
        Two-sided 95 % interval of one value (of the gated chi2 when the updates were gated).
    window_t_s : ndarray, shape (W + 1,)
        Edges of the windows (Unix s), or the first time of each group and the last time.
    window_medians : ndarray, shape (W,)
    window_label : str
        How the windows are made (``"median over 120 s"``).
    limit : float or None
        The health monitor's limit on a window's median (None: none drawn).
    limit_label : str
    """

    label: str
    t_s: FloatArray
    values: FloatArray
    dof: int
    band: tuple[float, float]
    window_t_s: FloatArray
    window_medians: FloatArray
    window_label: str
    limit: float | None = None
    limit_label: str = ""


def _plain(value: float, _pos: float) -> str:
    return f"{value:g}"


def plot_consistency(
    path: str | Path, panels: Sequence[ConsistencyPanel], t0_s: float, title: str
) -> Path:
    """One panel per :class:`ConsistencyPanel`, log scale, time from ``t0_s`` (s); a PNG."""
    n = max(len(panels), 1)
    fig = Figure(figsize=(9, 3.0 * n + 0.8), dpi=100, layout="constrained")
    axes = fig.subplots(n, 1, sharex=True, squeeze=False)[:, 0]
    for ax, p in zip(axes, panels, strict=False):
        lo, hi = p.band
        v = np.maximum(p.values, 1e-6)
        inside = float(np.mean((p.values >= lo) & (p.values <= hi))) if v.size else float("nan")
        ax.semilogy(
            p.t_s - t0_s,
            v,
            ".",
            ms=2.0,
            color="tab:blue",
            alpha=0.5,
            label=textwrap.fill(f"{p.label} (K={v.size})", 64),
        )
        ax.axhspan(
            lo,
            hi,
            color="tab:green",
            alpha=0.15,
            label=f"95 % band of one value: {100 * inside:.0f} % inside",
        )
        if p.window_medians.size:
            med = np.append(p.window_medians, p.window_medians[-1])
            ax.step(
                p.window_t_s - t0_s,
                np.maximum(med, 1e-6),
                where="post",
                color="black",
                lw=1.6,
                label=p.window_label,
            )
        if p.limit is not None:
            ax.axhline(
                p.limit, color="tab:red", ls="--", lw=1.0, label=textwrap.fill(p.limit_label, 64)
            )
        ax.yaxis.set_major_formatter(FuncFormatter(_plain))
        ax.set_ylabel(f"chi2({p.dof}) units")
        ax.grid(True, which="both", lw=0.3)
        # above the panel, two columns: the data keep the figure's whole width
        ax.legend(
            loc="lower left",
            bbox_to_anchor=(0.0, 1.0),
            ncols=2,
            fontsize="x-small",
            frameon=False,
            borderaxespad=0.2,
        )
    if not panels:
        axes[0].text(0.5, 0.5, "no covariances: nothing to judge", ha="center", va="center")
    axes[-1].set_xlabel("time since the start (s)")
    fig.suptitle(title)
    out = Path(path)
    fig.savefig(out, bbox_inches="tight")
    return out
