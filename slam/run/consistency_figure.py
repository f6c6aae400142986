"""``consistency.png`` of a run directory: the run's NEES and NIS in time with their chi2 bands.

* Simulated data: the pose NEES (3 dof) of the estimate's own samples against the
  simulator's truth (:func:`sonarslam.slam.eval.consistency.nees_series`).
* Real data: the position NEES (2 dof) at every GPS fix with GPS's own sigma added to the
  estimate's covariance (:func:`sonarslam.slam.eval.consistency.gps_position_nees`); the sigma
  is the dataset configuration's ``[noise] gps_sigma_m``, named in the panel. A ruler only:
  nothing here feeds an estimator.
* Closed loops: the NIS of each kind of update the back end logged (line, heading, scan;
  :func:`sonarslam.slam.run.health.nis_streams`), with the band of the gated chi2 when the
  updates passed a gate (the quantiles ``p (1 -+ 0.95) / 2`` of chi2 for a gate of
  probability ``p``).

Each panel also draws the medians the health monitor judges (:mod:`sonarslam.slam.eval.health`:
NEES in windows of ``window_s``, NIS in groups of ``nis_window_updates``) and its limit for them.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from scipy.stats import chi2

from sonarslam.datasets.source import Dataset
from sonarslam.slam.eval.consistency import (
    NeesSeries,
    chi2_band,
    gps_position_nees,
    nees_series,
    window_median_gate,
    window_medians,
)
from sonarslam.slam.eval.health import HealthConfig, NisStream
from sonarslam.slam.eval.truth import truth_trajectory
from sonarslam.slam.io.consistency_plots import ConsistencyPanel, plot_consistency
from sonarslam.slam.io.trajectory import Trajectory

__all__ = ["CONSISTENCY_FILE", "nees_panel", "nis_panel", "write_consistency_figure"]

#: The figure's name in a run directory.
CONSISTENCY_FILE = "consistency.png"


def nees_panel(
    dataset: Dataset, trajectory: Trajectory, cfg: HealthConfig
) -> ConsistencyPanel | None:
    """The NEES panel: against the truth (simulated data) or GPS with its sigma (real data);
    None without covariances or a reference inside the run."""
    if trajectory.covs is None:
        return None
    series: NeesSeries
    if dataset.truth is not None:
        series = nees_series(trajectory, truth_trajectory(dataset), "pose")
        label = "pose NEES against the simulator's truth"
    elif dataset.gps is not None:
        sigma = float(dataset.config.noise.gps_sigma_m)
        series = gps_position_nees(trajectory, dataset.gps.t, dataset.gps.en_m, sigma)
        label = (
            f"position NEES against GPS (+ GPS sigma {sigma:g} m:"
            " the dataset configuration's [noise] gps_sigma_m)"
        )
    else:
        return None
    if series.t_s.size == 0:
        return None
    edges, medians = window_medians(series, cfg.window_s)
    edges[-1] = min(float(edges[-1]), float(series.t_s[-1]))  # the last window ends with the run
    n = int(np.sum(np.isfinite(medians)))
    limit = window_median_gate(series.dof, max(n, 1), cfg.false_alarm)
    return ConsistencyPanel(
        label,
        series.t_s,
        series.nees,
        series.dof,
        chi2_band(series.dof),
        edges,
        medians,
        f"median over {cfg.window_s:g} s",
        limit,
        f"health monitor's limit on a window's median ({limit:.1f})",
    )


def nis_panel(stream: NisStream, cfg: HealthConfig) -> ConsistencyPanel:
    """The NIS of one kind of update, with the band of its gated chi2 and the medians of the
    monitor's groups of updates."""
    order = np.argsort(stream.t_s, kind="stable")
    t, v = stream.t_s[order], stream.nis[order]
    p = 1.0 if stream.gate_probability is None else stream.gate_probability
    lo, hi = (float(x) for x in chi2.ppf([0.025 * p, 0.975 * p], stream.dof))
    starts = np.arange(0, t.size, cfg.nis_window_updates)
    medians = np.array([float(np.median(v[a : a + cfg.nis_window_updates])) for a in starts])
    edges = np.append(t[starts], t[-1]) if t.size else np.zeros(1)
    limit = cfg.nis_scale_max * float(chi2.ppf(p / 2.0, stream.dof))
    gated = f", gated at {p:g}" if stream.gate_probability is not None else ""
    return ConsistencyPanel(
        f"{stream.kind} NIS{gated}",
        t,
        v,
        stream.dof,
        (lo, hi),
        edges,
        medians,
        f"median of {cfg.nis_window_updates} updates",
        limit,
        f"{cfg.nis_scale_max:g}x the chi2 median: the monitor flags a group whose median's"
        " lower bound is beyond",
    )


def write_consistency_figure(
    path: Path,
    dataset: Dataset,
    label: str,
    trajectory: Trajectory,
    streams: list[NisStream],
    cfg: HealthConfig | None = None,
) -> Path:
    """Draw ``consistency.png`` (module docstring) into ``path``."""
    config = cfg or HealthConfig()
    panels = [nees_panel(dataset, trajectory, config)] + [nis_panel(s, config) for s in streams]
    drawn = [p for p in panels if p is not None]
    return plot_consistency(
        path,
        drawn,
        float(trajectory.t_s[0]),
        f"{dataset.name}: {label}, consistency in time (log scale)",
    )
