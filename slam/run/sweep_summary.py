"""The sweep's scores: each run against the truth and against dead reckoning on its own seed, and
one summary row per configuration (:func:`sonarslam.slam.run.sweep.sweep` writes them).

A sweep runs on simulated worlds, so it scores against the **truth**, not simulated GPS: per run
the ATE against the true poses (``ate_truth_mean_m``) and after a rigid alignment onto them
(``ate_truth_aligned_mean_m``, the shape error; :func:`sonarslam.slam.eval.ate.ate_against_truth`), both
written by :func:`sonarslam.slam.run.run.run_backend`. Each run is paired with the dead-reckoning run of the
same seed (:func:`pair_with_baseline`): ``beats_dr`` (1 when its ATE is below dead reckoning's,
0 when not) and ``gain_over_dr`` (``1 - ATE / ATE_dr``), for both ATEs. Per configuration
(:func:`summarise`): the share of its seeds on which it beats dead reckoning, its gain in the
mean (``1 - mean ATE / mean ATE_dr`` over the paired seeds) and the spread of the per-seed gain
(p10 / p50 / p90 and the worst), beside the ANEES with its band (:mod:`sonarslam.slam.eval.consistency`)
and the association scores against the true walls. A back end that smooths gets a second row
for its smoothed trajectory (``isam2 smoothed``), scored the same way against the same dead
reckoning. :func:`worst_seeds` lists the seeds where a configuration gains least, with their
world's geometry (:func:`world_columns`), and :func:`format_spread` writes it all as Markdown
(the sweep's ``spread.md``).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import pandas as pd

from sonarslam.slam.eval.consistency import anees

__all__ = [
    "BASELINE",
    "PAIRED_ATES",
    "VIEWS",
    "config_columns",
    "config_labels",
    "pair_with_baseline",
    "summarise",
    "worst_seeds",
    "world_columns",
    "format_summary",
    "format_spread",
    "held_back_note",
]

#: The back end every run is paired with, seed by seed.
BASELINE = "dr"

#: The ATEs paired with the baseline's: the run's column, the baseline's column, and the suffix
#: of the paired columns. A smoothed trajectory is paired with the baseline's only one.
PAIRED_ATES = (
    ("ate_truth_mean_m", "ate_truth_mean_m", ""),
    ("ate_truth_aligned_mean_m", "ate_truth_aligned_mean_m", "_aligned"),
    ("ate_truth_smoothed_mean_m", "ate_truth_mean_m", "_smoothed"),
    ("ate_truth_aligned_smoothed_mean_m", "ate_truth_aligned_mean_m", "_aligned_smoothed"),
)

#: The trajectories of a run that get a summary row: the name appended to the configuration,
#: and the suffix of their ATE columns (``ate_truth<suffix>_mean_m``) and paired columns.
VIEWS = (("", ""), ("smoothed", "_smoothed"))

#: Quantiles of the per-seed gain over the baseline in the summary (``gain_over_dr_p10``, ...).
GAIN_QUANTILES = (10, 50, 90)

#: What the terminal shows of a summary (the rest is in ``summary.csv``).
TERMINAL_COLUMNS = (
    "config",
    "runs",
    "failed",
    "ate_truth_mean_m",
    "ate_truth_aligned_mean_m",
    "beats_dr_share",
    "gain_over_dr_p50",
    "gain_over_dr_min",
    "beats_dr_aligned_share",
    "gain_over_dr_aligned_p50",
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

    For each ``(column, baseline column, suffix)`` of :data:`PAIRED_ATES` whose column the table
    has, adds ``dr<suffix>_ate_m`` (the baseline's ATE on that seed), ``beats_dr<suffix>`` (1.0
    when the run's ATE is below it, 0.0 when not) and ``gain_over_dr<suffix>`` (``1 - ATE /
    ATE_dr``). They are NaN on the baseline's own rows, on failed runs, on runs without that
    trajectory and on seeds where the baseline has no successful run.

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
    for column, base_column, suffix in PAIRED_ATES:
        if column not in table:
            continue
        ate = table[column].to_numpy(dtype=float)
        base = (
            table[base_column].to_numpy(dtype=float)
            if base_column in table
            else np.full(len(table), np.nan)
        )
        base_of_seed = {
            int(s): a
            for s, a, b, good in zip(table["seed"], base, is_base, ok, strict=True)
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


def _paired_scores(good: pd.DataFrame, view: str = "") -> dict[str, Any]:
    """Share of seeds beating the baseline, gain in the mean and the spread of the per-seed gain
    over a configuration's paired runs (:func:`pair_with_baseline`), for the trajectory of
    ``view`` (a suffix of :data:`VIEWS`); named as the plain trajectory's (``gain_over_dr``,
    ``gain_over_dr_aligned_p50``, ...)."""
    rec: dict[str, Any] = {}
    columns = {suffix: column for column, _, suffix in PAIRED_ATES}
    for name in ("", "_aligned"):
        suffix = f"{name}{view}"
        column = columns[suffix]
        ref_col = f"dr{suffix}_ate_m"
        if ref_col not in good or column not in good:
            continue
        ref = good[ref_col].to_numpy(dtype=float)
        paired = np.isfinite(ref)
        if not paired.any():
            continue
        ate = good[column].to_numpy(dtype=float)[paired]
        beats = good[f"beats_dr{suffix}"].to_numpy(dtype=float)[paired]
        gain = good[f"gain_over_dr{suffix}"].to_numpy(dtype=float)[paired]
        rec[f"dr_pairs{name}"] = int(paired.sum())
        rec[f"beats_dr{name}_seeds"] = int(beats.sum())
        rec[f"beats_dr{name}_share"] = float(beats.mean())
        rec[f"gain_over_dr{name}"] = float(1.0 - ate.mean() / ref[paired].mean())
        for q in GAIN_QUANTILES:
            rec[f"gain_over_dr{name}_p{q}"] = float(np.percentile(gain, q))
        rec[f"gain_over_dr{name}_min"] = float(gain.min())
        rec[f"worse_than_dr{name}_by_10pct_seeds"] = int(np.count_nonzero(gain < -0.10))
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
    """One row per configuration (back end and parameter values) and trajectory over its seeds.

    Columns: the configuration (``config``: its label, with `` smoothed`` for a smoothed
    trajectory), ``trajectory`` (``""`` or ``"smoothed"``), ``runs``, ``failed``; against the
    truth, the means over the runs of ``ate_truth_mean_m`` (with ``ate_truth_mean_sd_m``, their
    spread over the seeds), ``ate_truth_max_m``, ``ate_truth_rmse_m`` and
    ``ate_truth_aligned_mean_m`` (of that trajectory); paired with dead reckoning by seed
    (``table`` from :func:`pair_with_baseline`; not on the baseline's own row): ``dr_pairs``,
    ``beats_dr_seeds``, ``beats_dr_share``, ``gain_over_dr`` (``1 - mean ATE / mean ATE_dr``
    over those seeds), the per-seed gain's ``gain_over_dr_p10``, ``_p50``, ``_p90`` and ``_min``
    (the worst seed), ``worse_than_dr_by_10pct_seeds``, and the same with ``_aligned``;
    ``anees`` (pose, 3 dof: mean over time of the mean over runs), ``anees_in_band_fraction``
    (times whose ANEES is inside the 95 % band of that many runs), ``anees_band_lo/hi`` (for all
    the runs), ``anees_position`` (2 dof) and its band (the online trajectory's: a smoothed one
    has no covariances), ``wall_s`` (mean); for closed loops, ``assoc_precision`` and
    ``assoc_recall`` against the true walls, pooled over the runs, and ``assoc_pairings``.
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
        for view, suffix in VIEWS:
            mean_col = f"ate_truth{suffix}_mean_m"
            if view and (mean_col not in good or not np.isfinite(good[mean_col]).any()):
                continue
            rec: dict[str, Any] = {"config": f"{k} {view}".strip(), "trajectory": view}
            rec.update({c: sub.iloc[0][c] for c in cols})
            rec.update(runs=int(ok.size), failed=int(idx.size - ok.size))
            if ok.size:
                rec.update(_view_scores(good, suffix))
                rec.update(_paired_scores(good, suffix))
                rec["wall_s"] = float(good["wall_s"].mean())
                rec.update(_assoc_scores(good))
                if not view:
                    rec.update(_anees_scores(ok, nees_pose, nees_position))
            out.append(rec)
    return pd.DataFrame(out)


def _view_scores(good: pd.DataFrame, suffix: str) -> dict[str, Any]:
    """The ATE means against the truth of one trajectory (``suffix``: ``""``, ``"_smoothed"``)."""
    rec: dict[str, Any] = {}
    mean_col = f"ate_truth{suffix}_mean_m"
    rec["ate_truth_mean_m"] = _mean_of(good, mean_col)
    rec["ate_truth_mean_sd_m"] = (
        float(good[mean_col].std(ddof=1)) if len(good) > 1 and mean_col in good else 0.0
    )
    for stat in ("max", "rmse"):
        rec[f"ate_truth_{stat}_m"] = _mean_of(good, f"ate_truth{suffix}_{stat}_m")
    rec["ate_truth_aligned_mean_m"] = _mean_of(good, f"ate_truth_aligned{suffix}_mean_m")
    return rec


def _anees_scores(
    ok: np.ndarray, nees_pose: np.ndarray, nees_position: np.ndarray
) -> dict[str, Any]:
    rec: dict[str, Any] = {}
    for name, arr, dof in (("anees", nees_pose, 3), ("anees_position", nees_position, 2)):
        X = arr[ok] if arr.size else np.zeros((0, 0))
        if X.size and np.isfinite(X).any():
            s = anees(X, dof).summary()
            rec[name] = s["anees"]
            rec[f"{name}_in_band_fraction"] = s["anees_in_band_fraction"]
            rec[f"{name}_band_lo"] = s["anees_band_lo"]
            rec[f"{name}_band_hi"] = s["anees_band_hi"]
    return rec


#: The world's columns of a sweep row (:func:`world_columns`) that :func:`worst_seeds` shows.
WORLD_COLUMNS = (
    "world_basins",
    "world_channels",
    "world_features",
    "world_lap_s",
    "world_walls",
    "world_curved_walls",
    "err_ahrs_bias_deg",
    "err_dvl_scale",
)


def world_columns(truth: dict[str, Any] | None) -> dict[str, Any]:
    """The geometry and sensor errors of a simulated world (its ``truth.json``) as flat row
    columns: ``world_basins`` (how many), ``world_channels`` (``width x length m`` each, ``dead
    end`` marked), ``world_features`` (counts: breakwaters, docks, finger-pier groups,
    pontoons, hulls, coves, rounded corners), ``world_lap_s`` (one lap of the route at the
    layout's speed), ``world_walls``, ``world_curved_walls``, ``err_ahrs_bias_deg`` (the AHRS's
    constant bias), ``err_dvl_scale`` (the DVL's scale factor error). Empty without a layout."""
    if not truth or "layout" not in truth:
        return {}
    lay = truth["layout"]
    chans = "; ".join(
        f"{w:.0f}x{length:.0f}" + (" dead end" if dead else "")
        for w, length, dead in lay["channels"]
    )
    short = (
        ("breakwaters", "bw"), ("docks", "dk"), ("piers", "fp"), ("pontoons", "pn"),
        ("hulls", "hl"), ("coves", "cv"), ("rounded_corners", "rc"),
    )  # fmt: skip
    return {
        "world_basins": len(lay["basins"]),
        "world_channels": chans,
        "world_features": " ".join(f"{a}{lay.get(k, 0)}" for k, a in short),
        "world_lap_s": float(lay["lap_s"]),
        "world_walls": int(lay["walls"]),
        "world_curved_walls": int(lay["curved_walls"]),
        "err_ahrs_bias_deg": float(truth.get("noise", {}).get("ahrs_bias_deg", float("nan"))),
        "err_dvl_scale": float(truth.get("errors", {}).get("dvl_scale_factor", float("nan"))),
    }


def worst_seeds(table: pd.DataFrame, config: str, n: int = 5) -> pd.DataFrame:
    """The ``n`` seeds where a summary row's configuration (``summary["config"]``, e.g.
    ``"isam2 smoothed"``) gains least over dead reckoning (unaligned truth ATE), with its ATEs,
    gains, association scores, NEES and the world's geometry (:data:`WORLD_COLUMNS`)."""
    labels = config_labels(table)
    view, suffix = "", ""
    for v, sfx in VIEWS:
        if v and config.endswith(f" {v}"):
            view, suffix = v, sfx
    base = config.removesuffix(f" {view}") if view else config
    rows = table[(labels == base) & _succeeded(table)]
    gain_col = f"gain_over_dr{suffix}"
    if rows.empty or gain_col not in rows:
        return pd.DataFrame()
    rows = rows[np.isfinite(rows[gain_col].to_numpy(dtype=float))]
    rows = rows.sort_values(gain_col).head(n)
    show = {
        "seed": "seed",
        f"ate_truth{suffix}_mean_m": "ate_m",
        f"dr{suffix}_ate_m": "dr_ate_m",
        gain_col: "gain",
        f"gain_over_dr_aligned{suffix}": "gain_aligned",
        "truth_precision": "precision",
        "truth_recall": "recall",
        "gauge_ate_m": "gauge_m",
        **({} if view else {"nees_mean": "nees_mean"}),  # a smoothed trajectory has no NEES
        **{c: c for c in WORLD_COLUMNS},
    }
    present = [c for c in show if c in rows]
    return rows[present].rename(columns=show).reset_index(drop=True)


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


def _pct(v: Any) -> str:
    return "" if _missing(v) else f"{100.0 * float(v):+.0f} %"


def _share(rec: pd.Series, name: str) -> str:
    n, k = rec.get(f"dr_pairs{name}"), rec.get(f"beats_dr{name}_seeds")
    return "" if _missing(n) else f"{int(k)}/{int(n)}"


def held_back_note(seeds: list[int], held_back_min: int) -> str:
    """One line saying whether the seeds are the held-back ones (``>= held_back_min``)."""
    held = [s for s in seeds if s >= held_back_min]
    if len(held) == len(seeds):
        return (
            f"All {len(seeds)} seeds are held back (>= {held_back_min}): nothing was tuned on "
            "them, so these figures count."
        )
    if not held:
        return (
            f"Seeds below {held_back_min}: tuning seeds. Figures that count come from the "
            f"held-back seeds (>= {held_back_min})."
        )
    return (
        f"{len(held)} of {len(seeds)} seeds are held back (>= {held_back_min}); the others are "
        "tuning seeds: quote figures from held-back seeds only."
    )


def format_spread(
    summary: pd.DataFrame, table: pd.DataFrame, title: str, note: str = "", n_worst: int = 5
) -> str:
    """The spread of a sweep as Markdown: per configuration and trajectory, the share of seeds
    beating dead reckoning and the per-seed gain over it (p10 / p50 / p90, the worst), unaligned
    and aligned, the pose ANEES against its 95 % band and the association scores; then the
    ``n_worst`` seeds of each closed loop with their worlds (:func:`worst_seeds`)."""
    lines = [f"# Sweep: {title}", ""]
    if note:
        lines += [note, ""]
    head = (
        "| configuration | runs | ATE vs truth (m) | aligned (m) | beats DR | gain p10 / p50 / p90"
        " | worst | beats DR aligned | aligned gain p10 / p50 / p90 | worst | pose ANEES [95 % band]"
        " | precision / recall |"
    )
    lines += [head, "|" + "---|" * 12]
    for _, rec in summary.iterrows():
        qs = " / ".join(_pct(rec.get(f"gain_over_dr_p{q}")) for q in GAIN_QUANTILES)
        qa = " / ".join(_pct(rec.get(f"gain_over_dr_aligned_p{q}")) for q in GAIN_QUANTILES)
        anees_txt = (
            ""
            if _missing(rec.get("anees"))
            else f"{rec['anees']:.2f} [{rec['anees_band_lo']:.2f}, {rec['anees_band_hi']:.2f}]"
        )
        assoc = (
            ""
            if _missing(rec.get("assoc_precision"))
            else f"{100 * rec['assoc_precision']:.1f} % / {100 * rec['assoc_recall']:.1f} %"
        )
        ate, aligned = rec.get("ate_truth_mean_m"), rec.get("ate_truth_aligned_mean_m")
        lines.append(
            f"| {rec['config']} | {int(rec['runs'])} | "
            f"{'' if _missing(ate) else f'{ate:.2f}'} | "
            f"{'' if _missing(aligned) else f'{aligned:.3f}'} | {_share(rec, '')} | "
            f"{qs if not _missing(rec.get('gain_over_dr_p50')) else ''} | "
            f"{_pct(rec.get('gain_over_dr_min'))} | {_share(rec, '_aligned')} | "
            f"{qa if not _missing(rec.get('gain_over_dr_aligned_p50')) else ''} | "
            f"{_pct(rec.get('gain_over_dr_aligned_min'))} | {anees_txt} | {assoc} |"
        )
    lines += [
        "",
        "Gain: `1 - ATE / ATE_DR` on the same seed (positive: better than dead reckoning); "
        "`worst`: the lowest seed's.",
    ]
    for _, rec in summary.iterrows():
        if _missing(rec.get("dr_pairs")):
            continue
        worst = worst_seeds(table, str(rec["config"]), n_worst)
        if worst.empty:
            continue
        lines += ["", f"## The {len(worst)} worst seeds of {rec['config']}", ""]
        cols = list(worst.columns)
        lines += ["| " + " | ".join(cols) + " |", "|" + "---|" * len(cols)]
        for _, w in worst.iterrows():
            cells = []
            for c in cols:
                v = w[c]
                if c in ("gain", "gain_aligned"):
                    cells.append(_pct(v))
                elif isinstance(v, float):
                    cells.append("" if math.isnan(v) else f"{v:.3g}")
                else:
                    cells.append(str(v))
            lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"
