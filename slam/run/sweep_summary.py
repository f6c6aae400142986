"""The sweep's scores: each run against the truth and against dead reckoning on its own seed, and
one summary row per configuration (:func:`slam.run.sweep.sweep` writes them).

A sweep runs on simulated worlds, so it scores against the **truth**, not simulated GPS: per run
the ATE against the true poses (``ate_truth_mean_m``) and after a rigid alignment onto them
(``ate_truth_aligned_mean_m``, the shape error; :func:`slam.eval.ate.ate_against_truth`), both
written by :func:`slam.run.run.run_backend`. Each run is paired with the dead-reckoning run of the
same seed (:func:`pair_with_baseline`): ``beats_dr`` (1 when its ATE is below dead reckoning's,
0 when not) and ``gain_over_dr`` (``1 - ATE / ATE_dr``), for both ATEs. Per configuration
(:func:`summarise`): the share of its seeds on which it beats dead reckoning and its gain in the
mean (``1 - mean ATE / mean ATE_dr`` over the paired seeds), beside the ANEES with its band
(:mod:`slam.eval.consistency`) and the association scores against the true walls.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import pandas as pd

from slam.eval.consistency import anees

__all__ = [
    "BASELINE",
    "PAIRED_ATES",
    "config_columns",
    "config_labels",
    "pair_with_baseline",
    "summarise",
    "format_summary",
]

#: The back end every run is paired with, seed by seed.
BASELINE = "dr"

#: The ATEs paired with the baseline's: the run's column and the suffix of its paired columns.
PAIRED_ATES = (("ate_truth_mean_m", ""), ("ate_truth_aligned_mean_m", "_aligned"))

#: What the terminal shows of a summary (the rest is in ``summary.csv``).
TERMINAL_COLUMNS = (
    "config",
    "runs",
    "failed",
    "ate_truth_mean_m",
    "ate_truth_aligned_mean_m",
    "beats_dr_share",
    "gain_over_dr",
    "beats_dr_aligned_share",
    "gain_over_dr_aligned",
    "anees",
    "anees_band_lo",
    "anees_band_hi",
    "assoc_precision",
    "assoc_recall",
    "wall_s",
)


def config_columns(table: pd.DataFrame) -> list[str]:
    """The columns that name a configuration: ``backend`` and the grid axes (``scope.field``)."""
    return ["backend"] + sorted(c for c in table.columns if "." in c)


def _missing(v: Any) -> bool:
    return v is None or (isinstance(v, float) and math.isnan(v)) or v is pd.NA


def config_labels(table: pd.DataFrame) -> np.ndarray:
    """A label per row naming its configuration: ``"ekf association=nn"`` (the back end, then
    the parameter values that apply to it, scope dropped)."""
    params = config_columns(table)[1:]
    out = []
    for _, row in table.iterrows():
        parts = [str(row["backend"])]
        for c in params:
            if not _missing(row[c]):
                parts.append(f"{c.split('.', 1)[1]}={row[c]}")
        out.append(" ".join(parts))
    return np.array(out, dtype=object)


def _succeeded(table: pd.DataFrame) -> np.ndarray:
    if "error" not in table:
        return np.ones(len(table), dtype=bool)
    return (table["error"].fillna("") == "").to_numpy()


def pair_with_baseline(table: pd.DataFrame, baseline: str = BASELINE) -> pd.DataFrame:
    """The table with each run paired with the baseline's run on the same seed.

    For each ``(column, suffix)`` of :data:`PAIRED_ATES`, adds ``dr<suffix>_ate_m`` (the
    baseline's ATE on that seed), ``beats_dr<suffix>`` (1.0 when the run's ATE is below it, 0.0
    when not) and ``gain_over_dr<suffix>`` (``1 - ATE / ATE_dr``). They are NaN on the
    baseline's own rows, on failed runs and on seeds where the baseline has no successful run
    (or the column is missing: runs without a truth).

    Parameters
    ----------
    table : DataFrame
        One row per run with ``seed``, ``backend``, ``error`` and the ATE columns.
    baseline : str
        The back end to pair with.

    Returns
    -------
    DataFrame
        A copy of ``table`` with the added columns.
    """
    out = table.copy()
    ok = _succeeded(table)
    is_base = (table["backend"] == baseline).to_numpy() if len(table) else np.zeros(0, bool)
    for column, suffix in PAIRED_ATES:
        ate = (
            table[column].to_numpy(dtype=float) if column in table else np.full(len(table), np.nan)
        )
        base_of_seed = {
            int(s): a
            for s, a, b, good in zip(table["seed"], ate, is_base, ok, strict=True)
            if b and good and np.isfinite(a)
        }
        ref = np.array(
            [
                base_of_seed.get(int(s), np.nan) if good and not b else np.nan
                for s, b, good in zip(table["seed"], is_base, ok, strict=True)
            ],
            dtype=float,
        )
        paired = np.isfinite(ref) & np.isfinite(ate)
        with np.errstate(invalid="ignore", divide="ignore"):
            out[f"dr{suffix}_ate_m"] = np.where(paired, ref, np.nan)
            out[f"beats_dr{suffix}"] = np.where(paired, (ate < ref).astype(float), np.nan)
            out[f"gain_over_dr{suffix}"] = np.where(paired, 1.0 - ate / ref, np.nan)
    return out


def _paired_scores(good: pd.DataFrame) -> dict[str, Any]:
    """Share of seeds beating the baseline and gain in the mean, over a configuration's paired
    runs (:func:`pair_with_baseline`)."""
    rec: dict[str, Any] = {}
    for column, suffix in PAIRED_ATES:
        ref_col = f"dr{suffix}_ate_m"
        if ref_col not in good or column not in good:
            continue
        ref = good[ref_col].to_numpy(dtype=float)
        paired = np.isfinite(ref)
        if not paired.any():
            continue
        ate = good[column].to_numpy(dtype=float)[paired]
        beats = good[f"beats_dr{suffix}"].to_numpy(dtype=float)[paired]
        rec[f"dr_pairs{suffix}"] = int(paired.sum())
        rec[f"beats_dr{suffix}_seeds"] = int(beats.sum())
        rec[f"beats_dr{suffix}_share"] = float(beats.mean())
        rec[f"gain_over_dr{suffix}"] = float(1.0 - ate.mean() / ref[paired].mean())
    return rec


def _assoc_scores(good: pd.DataFrame) -> dict[str, Any]:
    """Association precision and recall against the true walls, pooled over the runs: every
    pairing (re-observation) weighs the same."""
    if "truth_precision" not in good or good["truth_associations"].fillna(0).sum() <= 0:
        return {}
    n = good["truth_associations"].fillna(0)
    m = good["truth_reobservations"].fillna(0)
    return {
        "assoc_precision": float((good["truth_precision"].fillna(0) * n).sum() / n.sum()),
        "assoc_recall": float((good["truth_recall"].fillna(0) * m).sum() / max(m.sum(), 1)),
        "assoc_pairings": int(n.sum()),
    }


def _mean_of(good: pd.DataFrame, column: str) -> float:
    return float(good[column].mean()) if column in good else float("nan")


def summarise(
    table: pd.DataFrame, nees_pose: np.ndarray, nees_position: np.ndarray
) -> pd.DataFrame:
    """One row per configuration (back end and parameter values) over its seeds.

    Columns: the configuration, ``runs``, ``failed``; against the truth, the means over the runs
    of ``ate_truth_mean_m`` (with ``ate_truth_mean_sd_m``, their spread over the seeds),
    ``ate_truth_max_m``, ``ate_truth_rmse_m`` and ``ate_truth_aligned_mean_m``; paired with dead
    reckoning by seed (``table`` from :func:`pair_with_baseline`; not on the baseline's own row):
    ``dr_pairs``, ``beats_dr_seeds``, ``beats_dr_share`` and ``gain_over_dr``
    (``1 - mean ATE / mean ATE_dr`` over those seeds), and the same with ``_aligned``;
    ``anees`` (pose, 3 dof: mean over time of the mean over runs), ``anees_in_band_fraction``
    (times whose ANEES is inside the 95 % band of that many runs), ``anees_band_lo/hi`` (for all
    the runs), ``anees_position`` (2 dof) and its band, ``wall_s`` (mean); for closed loops,
    ``assoc_precision`` and ``assoc_recall`` against the true walls, pooled over the runs, and
    ``assoc_pairings``.
    """
    cols = config_columns(table)
    key = config_labels(table)
    succeeded = _succeeded(table)
    out = []
    for k in dict.fromkeys(key):
        idx = np.flatnonzero(key == k)
        sub = table.iloc[idx]
        ok = idx[succeeded[idx]]
        good = table.iloc[ok]
        rec: dict[str, Any] = {"config": k, **{c: sub.iloc[0][c] for c in cols}}
        rec.update(runs=int(ok.size), failed=int(idx.size - ok.size))
        if ok.size:
            rec["ate_truth_mean_m"] = _mean_of(good, "ate_truth_mean_m")
            rec["ate_truth_mean_sd_m"] = (
                float(good["ate_truth_mean_m"].std(ddof=1))
                if ok.size > 1 and "ate_truth_mean_m" in good
                else 0.0
            )
            for column in ("ate_truth_max_m", "ate_truth_rmse_m", "ate_truth_aligned_mean_m"):
                rec[column] = _mean_of(good, column)
            rec.update(_paired_scores(good))
            rec["wall_s"] = float(good["wall_s"].mean())
            rec.update(_assoc_scores(good))
            for name, arr, dof in (("anees", nees_pose, 3), ("anees_position", nees_position, 2)):
                X = arr[ok] if arr.size else np.zeros((0, 0))
                if X.size and np.isfinite(X).any():
                    s = anees(X, dof).summary()
                    rec[name] = s["anees"]
                    rec[f"{name}_in_band_fraction"] = s["anees_in_band_fraction"]
                    rec[f"{name}_band_lo"] = s["anees_band_lo"]
                    rec[f"{name}_band_hi"] = s["anees_band_hi"]
        out.append(rec)
    return pd.DataFrame(out)


def format_summary(summary: pd.DataFrame, brief: bool = False) -> str:
    """The summary as aligned text for the terminal; ``brief``: only the columns of
    :data:`TERMINAL_COLUMNS` that it has."""
    if summary.empty:
        return "(no runs)"
    show = summary.copy()
    if brief:
        show = show[[c for c in TERMINAL_COLUMNS if c in show]]
    for c in show.columns:
        if show[c].dtype.kind == "f":
            show[c] = show[c].map(lambda v: "" if math.isnan(v) else f"{v:.3g}")
    return show.to_string(index=False)
