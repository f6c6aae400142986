"""Filter consistency against a known truth: NEES, NIS and ANEES with their chi2 bands.

* pose NEES ``e_k^T P_k^-1 e_k``, ``e_k = (x - x_true, y - y_true, wrap(psi - psi_true))``
  (:func:`sonarslam.features.geometry.wrap_angle`), chi2 with 3 degrees of freedom when consistent (2 for
  the position only, 1 for the heading only);
* NIS of the innovations when a back end logs them (:func:`nis`);
* the one-sided gate of one chi2 value (:func:`chi2_gate`), whose exceedances a consistent
  estimator has with the gate's complement probability;
* windows of one run (:func:`window_medians`) and the gate of their medians that holds its
  level whatever the correlation of a window's samples (:func:`window_median_gate`), which the
  health monitor and the run's ``consistency.png`` share;
* the position NEES against GPS fixes with GPS's own sigma added (:func:`gps_position_nees`),
  for real data;
* ANEES over N Monte Carlo runs: at each time the mean of the N NEES, whose two-sided 95 %
  band is ``chi2.ppf([0.025, 0.975], N dof) / N`` (Bar-Shalom, Li, Kirubarajan 2001, 5.4.2).

The one place of the NEES and of its chi2 bands: trajectories (here), line features against
true walls (:mod:`sonarslam.slam.eval.lines`), the report and the sweep all use these.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt
from scipy import stats

from sonarslam.features.geometry import FloatArray, wrap_angle
from sonarslam.slam.io.trajectory import Trajectory

__all__ = [
    "NEES_PROBABILITY",
    "COMPONENTS",
    "NeesSeries",
    "AneesResult",
    "pose_errors",
    "nees",
    "nees_series",
    "nis",
    "chi2_band",
    "chi2_gate",
    "mean_nees_band",
    "nees_on_grid",
    "anees",
    "window_medians",
    "window_median_gate",
    "gps_position_nees",
]

#: Probability of the two-sided consistency bands.
NEES_PROBABILITY = 0.95


#: The pose components of a NEES: indices into ``(x_m, y_m, yaw_rad)``.
COMPONENTS: dict[str, tuple[int, ...]] = {"pose": (0, 1, 2), "position": (0, 1), "heading": (2,)}


@dataclass(frozen=True)
class NeesSeries:
    """NEES (or NIS) values against time.

    Attributes
    ----------
    t_s : ndarray, shape (K,)
        Unix times (s).
    nees : ndarray, shape (K,)
        Normalised errors squared.
    dof : int
        Degrees of freedom of each value (chi2 when consistent).
    """

    t_s: FloatArray
    nees: FloatArray
    dof: int

    @property
    def mean(self) -> float:
        return float(np.mean(self.nees)) if self.nees.size else float("nan")

    def in_band_fraction(self, probability: float = NEES_PROBABILITY) -> float:
        """Fraction of the values inside the two-sided ``probability`` band of chi2(dof)."""
        lo, hi = chi2_band(self.dof, probability)
        return float(np.mean((self.nees >= lo) & (self.nees <= hi))) if self.nees.size else 0.0


def pose_errors(estimate: Trajectory, truth: Trajectory, t_s: npt.ArrayLike) -> FloatArray:
    """``estimate - truth`` at ``t_s`` (both interpolated), yaw wrapped; shape (K, 3) (m, m, rad)."""
    e = estimate.poses(t_s) - truth.poses(t_s)
    e[:, 2] = wrap_angle(e[:, 2])
    return e


def nees(errors: npt.ArrayLike, covs: npt.ArrayLike) -> FloatArray:
    """``e_k^T P_k^-1 e_k`` of errors (K, d) with covariances (K, d, d); shape (K,)."""
    e = np.asarray(errors, dtype=np.float64)
    P = np.asarray(covs, dtype=np.float64)
    return np.einsum("ki,ki->k", e, np.linalg.solve(P, e[:, :, None])[:, :, 0])


def nees_series(
    estimate: Trajectory,
    truth: Trajectory,
    components: str = "pose",
    period_s: float | None = None,
) -> NeesSeries:
    """NEES of an estimate's own samples against the truth.

    Parameters
    ----------
    estimate : Trajectory
        With covariances.
    truth : Trajectory
        Interpolated at the estimate's times (only those inside its span are used).
    components : {"pose", "position", "heading"}
        Which block of ``(x, y, yaw)`` (3, 2 or 1 degrees of freedom).
    period_s : float, optional
        Keep one sample per ``period_s`` (the last at or before each multiple of it after the
        start); default every sample.

    Returns
    -------
    NeesSeries
    """
    if estimate.covs is None:
        raise ValueError("NEES needs the trajectory covariances (trajectory_cov.npz)")
    if components not in COMPONENTS:
        raise ValueError(f"components must be one of {sorted(COMPONENTS)}, got {components!r}")
    idx = np.asarray(COMPONENTS[components])
    t = estimate.t_s
    keep = np.flatnonzero((t >= truth.t_s[0]) & (t <= truth.t_s[-1]))
    if period_s is not None and keep.size:
        grid = np.arange(t[keep[0]], t[keep[-1]] + 0.5 * period_s, period_s)
        pick = np.searchsorted(t[keep], grid, side="right") - 1
        keep = keep[np.unique(pick[pick >= 0])]
    e = pose_errors(estimate, truth, t[keep])[:, idx]
    P = np.asarray(estimate.covs)[keep][:, idx[:, None], idx[None, :]]
    return NeesSeries(t[keep].copy(), nees(e, P), int(idx.size))


def nis(
    t_s: npt.ArrayLike, innovations: npt.ArrayLike, innovation_covs: npt.ArrayLike
) -> NeesSeries:
    """NIS ``nu^T S^-1 nu`` of logged innovations (K, d) and their covariances (K, d, d).

    For back ends that log their innovations (line observations: ``d = 2``); none does yet.
    """
    nu = np.asarray(innovations, dtype=np.float64)
    return NeesSeries(np.asarray(t_s, dtype=np.float64), nees(nu, innovation_covs), nu.shape[1])


def chi2_band(dof: int, probability: float = NEES_PROBABILITY) -> tuple[float, float]:
    """Two-sided ``probability`` interval of one chi2(``dof``) value."""
    return mean_nees_band(1, dof, probability)


def chi2_gate(dof: int, probability: float) -> float:
    """One-sided gate ``chi2.ppf(probability, dof)``: a consistent NEES with ``dof`` degrees of
    freedom lies beyond it with probability ``1 - probability`` (9.210 at 0.99 and 2 dof)."""
    if dof < 1 or not 0.0 < probability < 1.0:
        raise ValueError(f"need dof >= 1 and 0 < probability < 1, got {dof}, {probability}")
    return float(stats.chi2.ppf(probability, dof))


def mean_nees_band(
    n_runs: int, dof: int, probability: float = NEES_PROBABILITY
) -> tuple[float, float]:
    """Two-sided ``probability`` interval of the mean of ``n_runs`` independent chi2(``dof``).

    ``chi2.ppf([(1 - p) / 2, (1 + p) / 2], n_runs dof) / n_runs``; at 0.95 and 3 dof: (0.216,
    9.348) for one run, (2.360, 3.716) for 50.
    """
    if n_runs < 1 or dof < 1:
        raise ValueError(f"need n_runs >= 1 and dof >= 1, got {n_runs}, {dof}")
    a = 0.5 * (1.0 - probability)
    lo, hi = stats.chi2.ppf([a, 1.0 - a], n_runs * dof) / n_runs
    return float(lo), float(hi)


def nees_on_grid(series: NeesSeries, t0_s: float, grid_rel_s: npt.ArrayLike) -> FloatArray:
    """The series' value at each time ``t0_s + grid_rel_s`` (the last at or before it; NaN
    before the first and more than one grid step after the last), shape (K,)."""
    g = t0_s + np.asarray(grid_rel_s, dtype=np.float64)
    out = np.full(g.size, np.nan)
    if series.t_s.size == 0:
        return out
    step = float(np.median(np.diff(g))) if g.size > 1 else np.inf
    i = np.searchsorted(series.t_s, g, side="right") - 1
    ok = (i >= 0) & (g - series.t_s[np.clip(i, 0, None)] <= step)
    out[ok] = series.nees[i[ok]]
    return out


@dataclass(frozen=True)
class AneesResult:
    """ANEES over Monte Carlo runs on a common time grid.

    Attributes
    ----------
    t_rel_s : ndarray, shape (K,)
        Time since the start of the runs (s).
    anees : ndarray, shape (K,)
        Mean NEES over the runs that have a value at each time.
    n_runs : ndarray of int, shape (K,)
        Runs averaged at each time.
    dof : int
    band_lo, band_hi : ndarray, shape (K,)
        Two-sided band of the mean of ``n_runs`` chi2(dof) at each time.
    """

    t_rel_s: FloatArray
    anees: FloatArray
    n_runs: npt.NDArray[np.int64]
    dof: int
    band_lo: FloatArray
    band_hi: FloatArray
    probability: float = NEES_PROBABILITY

    @property
    def mean(self) -> float:
        """ANEES averaged over time."""
        ok = np.isfinite(self.anees)
        return float(np.mean(self.anees[ok])) if ok.any() else float("nan")

    @property
    def in_band_fraction(self) -> float:
        """Fraction of the times whose ANEES is inside its band (~``probability`` if consistent)."""
        ok = np.isfinite(self.anees)
        inside = (self.anees >= self.band_lo) & (self.anees <= self.band_hi)
        return float(np.mean(inside[ok])) if ok.any() else 0.0

    def summary(self) -> dict[str, Any]:
        """``anees``, ``anees_in_band_fraction``, ``anees_runs`` (most), ``anees_band_lo/hi`` (for
        that many runs), ``anees_dof``."""
        n = int(self.n_runs.max()) if self.n_runs.size else 0
        lo, hi = mean_nees_band(n, self.dof, self.probability) if n else (np.nan, np.nan)
        return {
            "anees": self.mean,
            "anees_in_band_fraction": self.in_band_fraction,
            "anees_runs": n,
            "anees_band_lo": lo,
            "anees_band_hi": hi,
            "anees_dof": self.dof,
        }

    def to_json(self) -> str:
        return json.dumps(
            {
                "t_rel_s": self.t_rel_s.tolist(),
                "anees": [None if not np.isfinite(v) else float(v) for v in self.anees],
                "n_runs": self.n_runs.tolist(),
                "dof": self.dof,
                **{k: v for k, v in self.summary().items() if k != "anees_dof"},
            }
        )


def anees(
    nees_runs: npt.ArrayLike,
    dof: int,
    t_rel_s: npt.ArrayLike | None = None,
    probability: float = NEES_PROBABILITY,
) -> AneesResult:
    """ANEES of Monte Carlo runs.

    Parameters
    ----------
    nees_runs : array_like, shape (N, K)
        NEES of run ``i`` at grid time ``k``; NaN where a run has no value.
    dof : int
        Degrees of freedom of one NEES.
    t_rel_s : array_like, shape (K,), optional
        The grid (s); default ``0, 1, ..., K - 1``.
    probability : float
        Of the two-sided band, ``chi2.ppf([(1-p)/2, (1+p)/2], n dof) / n`` at each time.
    """
    X = np.atleast_2d(np.asarray(nees_runs, dtype=np.float64))
    n = np.sum(np.isfinite(X), axis=0).astype(np.int64)
    with np.errstate(invalid="ignore", divide="ignore"):
        mean = np.where(n > 0, np.nansum(X, axis=0) / np.maximum(n, 1), np.nan)
    lo = np.full(X.shape[1], np.nan)
    hi = np.full(X.shape[1], np.nan)
    for m in np.unique(n[n > 0]):
        lo[n == m], hi[n == m] = mean_nees_band(int(m), dof, probability)
    grid = np.arange(X.shape[1], dtype=np.float64) if t_rel_s is None else np.asarray(t_rel_s)
    return AneesResult(grid, mean, n, dof, lo, hi, probability)


def window_medians(series: NeesSeries, window_s: float) -> tuple[FloatArray, FloatArray]:
    """Medians of a series in consecutive windows of ``window_s`` from its first time.

    Returns
    -------
    edges_s : ndarray, shape (W + 1,)
        Window edges (Unix s).
    medians : ndarray, shape (W,)
        Median of each window's values; NaN for a window without values.
    """
    t, v = series.t_s, series.nees
    if t.size == 0:
        return np.zeros(1), np.zeros(0)
    n = max(int(np.ceil((t[-1] - t[0]) / window_s)), 1)
    edges = t[0] + window_s * np.arange(n + 1, dtype=np.float64)
    which = np.clip(np.searchsorted(edges, t, side="right") - 1, 0, n - 1)
    medians = np.full(n, np.nan)
    for w in np.unique(which):
        medians[w] = float(np.median(v[which == w]))
    return edges, medians


def window_median_gate(dof: int, n_windows: int, false_alarm: float) -> float:
    """The gate of ``n_windows`` window medians of chi2(``dof``) values that a consistent run
    exceeds anywhere with probability at most ``false_alarm``, whatever the correlation of the
    values inside a window: ``chi2.ppf(1 - false_alarm / (2 W), dof)``. A median beyond ``c``
    needs half of the window's values beyond it, whose probability is at most twice that of one
    value (Markov's inequality on their count); Bonferroni over the windows."""
    if n_windows < 1:
        raise ValueError(f"need n_windows >= 1, got {n_windows}")
    return chi2_gate(dof, 1.0 - false_alarm / (2.0 * n_windows))


def gps_position_nees(
    estimate: Trajectory, gps_t_s: npt.ArrayLike, gps_en_m: npt.ArrayLike, gps_sigma_m: float
) -> NeesSeries:
    """Position NEES (2 dof) of an estimate at the GPS fixes inside its span, with the
    estimate's position covariance (its last sample at or before the fix) plus GPS's own
    ``gps_sigma_m**2 I``: ``d^T (P_xy + sigma^2 I)^-1 d``, ``d`` the estimate minus the fix.

    Position only: a GPS fix has no heading (the heading beside it in ``gps.tum`` is the
    AHRS's, which the estimators are given). Fix errors are not independent in time (GPS
    drifts), so judge it in windows (:func:`window_medians`, :func:`window_median_gate`).
    """
    if estimate.covs is None:
        raise ValueError("NEES needs the trajectory covariances (trajectory_cov.npz)")
    t = np.asarray(gps_t_s, dtype=np.float64)
    en = np.asarray(gps_en_m, dtype=np.float64)
    lo, hi = estimate.span_s
    inside = (t >= lo) & (t <= hi)
    t, en = t[inside], en[inside]
    d = estimate.poses(t)[:, :2] - en
    j = np.clip(np.searchsorted(estimate.t_s, t, side="right") - 1, 0, estimate.t_s.size - 1)
    S = np.asarray(estimate.covs)[j, :2, :2] + gps_sigma_m**2 * np.eye(2)
    return NeesSeries(t, nees(d, S), 2)
