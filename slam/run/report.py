"""A side-by-side report of run directories (``sonarslam report DIR... --out OUT``).

Reads what :func:`sonarslam.slam.run.run.run` wrote in each directory (:mod:`sonarslam.slam.run.report_data`),
re-opens the run's dataset when it is still there, and writes into ``OUT``:

* ``report.md``: per dataset, one table of its runs with the ATE over the **sonar span** (first
  to last sonar beam: where line landmarks can act) beside the ATE over the **whole navigation
  span**, the real-time factor and evo's APE / RPE; on simulated data the ATE against the
  simulator's truth (as it is and rigidly aligned) and the pose NEES. The published figures on
  the marina (Mallios et al. 2014, Table 2) stand under the marina's table only. Then the ATE
  per 300 s segment, the consistency over the simulated runs of each back end (ANEES), and the
  figures;
* ``trajectories_<dataset>.png``: the runs of one dataset against their reference (GPS, or the
  truth of a simulated run), in the plane and in time, the times without sonar shaded;
* ``segments_<dataset>.png``: the ATE per 300 s segment (mean bars, max marks);
* ``map_<run>.png``: the landmarks with their 95 % bands over the sonar bins projected with the
  run's trajectory, with its reference and the true walls of a simulated run;
* ``errors_<run>.png``: East, North (and heading, against the truth) errors in time with the
  3-sigma bounds of the trajectory covariances (and of the GPS noise against GPS);
* ``nees_<run>.png``: pose and position NEES in time with their chi2 bands (simulated runs);
* ``heading_error_<run>.png``: the AHRS heading error's track with its 2-sigma band (runs whose
  heading error walks, ``heading_error.csv``), with the simulator's true error;
* ``noise_<run>.png``: the noise the run learned over time (``noise.csv``, ``learn_noise``);
* ``consistency_<run>.png``: the run's own ``consistency.png`` (NEES against the truth or GPS,
  and a closed loop's NIS: :mod:`sonarslam.slam.run.consistency_figure`), when it wrote one.

Under each run's figures, its calibration estimates (``state_*`` of ``metrics.json``) with their
sd.
"""

from __future__ import annotations

import math
import shutil
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from sonarslam.slam.eval.consistency import (
    NeesSeries,
    anees,
    mean_nees_band,
    nees_on_grid,
    nees_series,
)
from sonarslam.slam.eval.published import PUBLISHED
from sonarslam.slam.run.report_data import (
    DISPLAY_NAMES,
    RunData,
    evaluate_run,
    load_run,
    safe_name,
    source_key,
    source_labels,
)
from sonarslam.slam.run.report_figures import (
    SegmentTable,
    calibration_lines,
    error_figure,
    heading_error_figure,
    learned_noise_figure,
    map_figure,
    nees_figure,
    segment_figure,
    segment_table,
    trajectory_figure,
)
from sonarslam.slam.run.report_free import (
    GpsFreeRun,
    gps_free_section,
    is_gps_free,
    load_gps_free,
)

__all__ = ["ReportResult", "report"]

#: The published rows stand under the tables of this dataset only.
PUBLISHED_DATASET = "marina"


@dataclass
class ReportResult:
    """The report's file, its figures and its table rows (every run's, then the published)."""

    path: Path
    figures: list[Path]
    rows: list[dict[str, Any]]


def _label(run: RunData, runs: list[RunData]) -> str:
    same = [
        r
        for r in runs
        if r.backend == run.backend and source_key(r.source) == source_key(run.source)
    ]
    return run.backend if len(same) == 1 else f"{run.backend} ({run.name})"


def _fmt(v: Any, digits: int = 2) -> str:
    if v is None or (isinstance(v, float) and not math.isfinite(v)):
        return ""
    if isinstance(v, str):
        return v
    if isinstance(v, int | np.integer):
        return f"{int(v):d}"
    if isinstance(v, float) and abs(v) >= 1000:
        return f"{v:,.0f}"
    return f"{v:.{digits}f}"


#: Columns (key, header) of a dataset's table: real data (against GPS), simulated (the truth).
_REAL_COLUMNS = [
    ("method", "method"),
    ("run", "run"),
    ("ate_sonar_mean_m", "sonar span: ATE mean (m)"),
    ("ate_sonar_sd_m", "sd"),
    ("ate_sonar_max_m", "max"),
    ("ate_sonar_n", "fixes"),
    ("ate_sonar_aligned_mean_m", "sonar span, SE(2)-aligned: mean"),
    ("ate_sonar_aligned_max_m", "max"),
    ("ate_mean_m", "whole run: ATE mean (m)"),
    ("ate_sd_m", "sd"),
    ("ate_min_m", "min"),
    ("ate_max_m", "max"),
    ("ate_rmse_m", "rmse"),
    ("ate_n", "fixes"),
    ("ate_aligned_mean_m", "whole run, aligned: mean"),
    ("realtime_factor", "real-time factor"),
    ("evo_ape_rmse_m", "evo APE rmse (m)"),
    ("evo_rpe_rmse_m", "evo RPE rmse (m)"),
]
_SIM_COLUMNS = [
    ("method", "method"),
    ("run", "run"),
    ("ate_truth_mean_m", "vs truth: ATE mean (m)"),
    ("ate_truth_max_m", "max"),
    ("ate_truth_aligned_mean_m", "aligned mean"),
    ("ate_sonar_mean_m", "vs GPS, sonar span: mean"),
    ("ate_mean_m", "vs GPS, whole run: mean"),
    ("realtime_factor", "real-time factor"),
    ("evo_ape_rmse_m", "evo APE rmse vs GPS (m)"),
    ("nees_mean", "pose NEES mean (3 dof)"),
    ("nees_in_band_fraction", "NEES in 95 % band"),
]


def _cell(key: str, v: Any) -> str:
    if v is None:
        return ""
    if key == "realtime_factor":
        return f"{_fmt(float(v), 0)}x"
    if key == "nees_in_band_fraction":
        return f"{100 * v:.0f} %"
    return _fmt(v)


def _markdown(rows: list[dict[str, Any]], columns: list[tuple[str, str]]) -> str:
    """A Markdown table (``pandas.DataFrame.to_markdown``, tabulate's pipe format)."""
    frame = pd.DataFrame(
        [[_cell(k, r.get(k)) for k, _ in columns] for r in rows], columns=[h for _, h in columns]
    )
    align = ["left" if i == 0 or k == "run" else "right" for i, (k, _) in enumerate(columns)]
    return str(frame.to_markdown(index=False, colalign=align, disable_numparse=True))


def _run_row(run: RunData, rpe_delta_m: float, align: bool) -> dict[str, Any]:
    ev = evaluate_run(run, rpe_delta_m, align)
    return {
        **run.metrics,
        **ev,
        "method": DISPLAY_NAMES.get(run.backend, run.backend) + " (ours)",
        "run": run.name,
        "dataset": run.dataset_name,
        "evo_rpe_rmse_m": ev.get(f"evo_rpe_{rpe_delta_m:g}m_rmse_m"),
        "evo_rpe_mean_m": ev.get(f"evo_rpe_{rpe_delta_m:g}m_mean_m"),
    }


#: A run's other trajectories (a factor graph's smoothed, batch, lines-re-decided and offline
#: estimates) by the suffix of their metrics.json keys, with the keys of the run's own row they
#: take.
_OTHER_TRAJECTORIES = ("smoothed", "batch", "redecided", "offline")


def _other_rows(run: RunData) -> list[dict[str, Any]]:
    """Rows of the run's other trajectories from its metrics.json (the ATE only: evo's figures
    are of ``<backend>.tum``)."""
    m = run.metrics
    rows = []
    for name in _OTHER_TRAJECTORIES:
        if f"ate_mean_{name}_m" not in m:
            continue
        row: dict[str, Any] = {
            "method": DISPLAY_NAMES.get(run.backend, run.backend) + f" (ours), {name}",
            "run": run.name,
            "dataset": run.dataset_name,
            "ate_mean_m": m[f"ate_mean_{name}_m"],
            "ate_max_m": m.get(f"ate_max_{name}_m"),
            "ate_aligned_mean_m": m.get(f"ate_aligned_mean_{name}_m"),
        }
        for key in ("ate_sonar", "ate_sonar_aligned", "ate_truth", "ate_truth_aligned"):
            for stat in ("mean_m", "sd_m", "max_m", "n"):
                row[f"{key}_{stat}"] = m.get(f"{key}_{name}_{stat}")
        rows.append(row)
    return rows


def _published_rows() -> list[dict[str, Any]]:
    """Mallios et al. 2014's rows; their span is not stated (their ATE runs along the SLAM
    trajectory, which a sonar SLAM has while its sonar runs), so they sit under the sonar span."""
    return [
        {
            "method": r["method"],
            "run": "published (Mallios 2014, Table 2)",
            "dataset": PUBLISHED_DATASET,
            "ate_sonar_mean_m": r["mean"],
            "ate_sonar_sd_m": r["sd"],
            "ate_sonar_min_m": r["min"],
            "ate_sonar_max_m": r["max"],
        }
        for r in PUBLISHED
    ]


def _segment_markdown(table: SegmentTable) -> str:
    edges = table.edges_s
    columns = [("method", "method")] + [
        (f"s{k}", f"{a:.0f}-{b:.0f} s")
        for k, (a, b) in enumerate(zip(edges[:-1], edges[1:], strict=True))
    ]
    rows = []
    for lab in table.mean_m:
        row: dict[str, Any] = {"method": lab}
        for k in range(edges.size - 1):
            m, x = table.mean_m[lab][k], table.max_m[lab][k]
            row[f"s{k}"] = "" if not np.isfinite(m) else f"{m:.2f} / {x:.2f}"
        rows.append(row)
    return _markdown(rows, columns)


def _consistency(runs: list[RunData], period_s: float = 1.0) -> list[str]:
    """ANEES per back end over the simulated runs given (one time grid from each start)."""
    by_backend: dict[str, list[NeesSeries]] = {}
    starts: dict[str, list[float]] = {}
    for run in runs:
        if run.truth is None or run.trajectory.covs is None:
            continue
        by_backend.setdefault(run.backend, []).append(nees_series(run.trajectory, run.truth))
        starts.setdefault(run.backend, []).append(run.trajectory.t_s[0])
    if not by_backend:
        return []
    rows = []
    for backend, series in by_backend.items():
        span = max(float(s.t_s[-1] - s.t_s[0]) for s in series if s.t_s.size)
        grid = np.arange(0.0, span + 1e-9, period_s)
        X = np.array(
            [nees_on_grid(s, t0, grid) for s, t0 in zip(series, starts[backend], strict=True)]
        )
        res = anees(X, 3, grid)
        lo, hi = mean_nees_band(len(series), 3)
        rows.append(
            {
                "back end": DISPLAY_NAMES.get(backend, backend),
                "runs N": str(len(series)),
                "ANEES (time mean)": f"{res.mean:.2f}",
                "95 % band for N": f"{lo:.2f} - {hi:.2f}",
                "times with ANEES in band": f"{100 * res.in_band_fraction:.0f} %",
            }
        )
    cols = [(k, k) for k in rows[0]]
    return [
        "## Consistency over the simulated runs",
        "",
        "Pose NEES (3 dof) of each run on a 1 s grid from its start; ANEES at each time is the "
        "mean over the runs, inside the two-sided 95 % band `chi2.ppf([0.025, 0.975], 3 N) / N` "
        "when consistent.",
        "",
        _markdown(rows, cols),
        "",
    ]


def _provenance(runs: list[RunData], labels: dict[str, str], free: list[GpsFreeRun]) -> list[str]:
    """Where each run's figures come from (``metrics.json``'s ``provenance``), the runs with GPS
    then those without."""
    rows = []
    named = [(f"{labels[str(r.run_dir)]} (`{r.name}`)", r.metrics) for r in runs]
    named += [(f"{r.metrics.get('backend')} (`{r.name}`)", r.metrics) for r in free]
    for name, metrics in named:
        p = metrics.get("provenance") or {}
        commit = p.get("git_commit")
        dirty = p.get("git_dirty")
        rows.append(
            {
                "run": name,
                "sonarslam": p.get("version") or "not recorded",
                "git commit": "not recorded"
                if commit is None
                else f"`{commit[:12]}`" + (" (dirty tree)" if dirty else ""),
                "settings sha256": f"`{p['settings_sha256'][:16]}`" if p else "",
                "dataset sha256": f"`{p['dataset_sha256'][:16]}` ({p['dataset_file_count']} files)"
                if p
                else "",
            }
        )
    cols = [(k, k) for k in rows[0]] if rows else []
    return [
        "## Provenance",
        "",
        "The code, settings and data of each run (`metrics.json`: `provenance`, full digests: "
        "SHA-256 of the resolved settings and of every file of the dataset).",
        "",
        _markdown(rows, cols),
        "",
    ]


def _dataset_section(
    name: str, group: list[RunData], rows: list[dict[str, Any]], segments: SegmentTable
) -> list[str]:
    simulated = any(r.truth is not None for r in group)
    md = [f"## {name}", ""]
    if simulated:
        md += [
            "Simulated: the ATE against the simulator's **truth** at every true pose of the run, "
            "as it is and after a rigid alignment (the shape error only); the simulated GPS "
            "columns follow the marina's protocol. No published figures apply here.",
            "",
            _markdown(rows, _SIM_COLUMNS),
        ]
    else:
        md += [
            "ATE (m) by the protocol of Mallios et al. 2014: at every GPS fix, the distance to "
            "the estimate interpolated there, no alignment (sd with ddof 1). **Sonar span**: the "
            "fixes from the first to the last sonar beam, where the line landmarks can act; "
            "**whole run**: every fix of the navigation (after the sonar stops every method is "
            "dead reckoning).",
            "",
            _markdown(rows, _REAL_COLUMNS),
        ]
        if name == PUBLISHED_DATASET:
            md += [
                "",
                "Published rows: Mallios et al. 2014, Table 2, whose span is not stated; they are "
                "set under the sonar span, where a sonar SLAM has its trajectory.",
            ]
    md += [
        "",
        f"### ATE per {segments.segment_s:.0f} s against {segments.reference} (mean / max, m)",
        "",
    ]
    if segments.sonar_end_s is not None:
        md += [f"The sonar stops {segments.sonar_end_s:.0f} s after the start.", ""]
    return md + [_segment_markdown(segments), "", *_health(group)]


def _health(group: list[RunData]) -> list[str]:
    """The health monitor's line of each closed loop (:mod:`sonarslam.slam.eval.health`)."""
    lines = [
        f"- {_label(r, group)}: {r.metrics['health_line']}"
        for r in group
        if isinstance(r.metrics.get("health_line"), str)
    ]
    if not lines:
        return []
    return ["### Health (GPS-free: each run against its own model)", "", *lines, ""]


def report(
    run_dirs: list[str | Path],
    out_dir: str | Path,
    rpe_delta_m: float = 10.0,
    align: bool = False,
    open_sources: bool = True,
) -> ReportResult:
    """Write ``report.md`` and its figures for run directories (module docstring).

    Parameters
    ----------
    run_dirs : list of str or Path
        Directories written by ``sonarslam run``.
    out_dir : str or Path
        Created if needed.
    rpe_delta_m : float
        Path length of evo's RPE pairs (m).
    align : bool
        Umeyama-align before evo's APE and RPE (the ATE protocol never aligns).
    open_sources : bool
        Re-open each run's dataset (reprojected map, GPS fixes, truth); False uses the run
        directories only.
    """
    if not run_dirs:
        raise ValueError("report: give at least one run directory")
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    free = [load_gps_free(d) for d in run_dirs if is_gps_free(d)]
    runs = [load_run(d, open_source=open_sources) for d in run_dirs if not is_gps_free(d)]
    labels = {str(r.run_dir): _label(r, runs) for r in runs}
    # one section per source (two bags of one file name in two folders are two datasets)
    names = source_labels(r.source for r in runs)
    by_dataset: dict[str, list[RunData]] = {}
    for run in runs:
        by_dataset.setdefault(names[run.source], []).append(run)
    rows: list[dict[str, Any]] = []
    figures: list[Path] = []
    md = [
        "# sonarslam report",
        "",
        f"Runs: {', '.join(f'`{r}`' for r in [*(x.run_dir for x in runs), *(x.run_dir for x in free)])}.",
        "",
    ]
    if runs:  # the runs with GPS (those without have their own section)
        md += [
            f"evo's APE is on `<backend>.tum` against `gps.tum` (translation, "
            f"{'Umeyama-aligned' if align else 'no alignment'}; its sd has ddof 0); evo's RPE is"
            f" the translation error of the relative motion over {rpe_delta_m:g} m of path.",
            "",
        ]
    dataset_figs: list[tuple[str, list[Path]]] = []
    for name, group in by_dataset.items():
        group_rows = [
            {**row, "dataset": name}
            for r in group
            for row in [_run_row(r, rpe_delta_m, align), *_other_rows(r)]
        ]
        if name == PUBLISHED_DATASET and not any(r.truth is not None for r in group):
            group_rows += _published_rows()
        rows += group_rows
        segments = segment_table(group, labels)
        md += _dataset_section(name, group, group_rows, segments)
        figs = [
            trajectory_figure(group, labels, out / f"trajectories_{safe_name(name)}.png"),
            segment_figure(segments, name, out / f"segments_{safe_name(name)}.png"),
        ]
        dataset_figs.append((name, figs))
        figures += figs
    free_md, free_figs, free_rows = gps_free_section(free, out)
    md += free_md
    figures += free_figs
    rows += free_rows
    md += _consistency(runs)
    md += _provenance(runs, labels, free)
    # the runs without GPS put their figures in their own section
    md += ["## Figures", ""] if runs else []
    for name, figs in dataset_figs:
        md += [f"### {name}", ""] + [f"![{p.stem}]({p.name})\n" for p in figs]
    for run in runs:
        lab = labels[str(run.run_dir)]
        tag = safe_name(run.name)
        figs = []
        if run.landmarks is not None:
            p = map_figure(run, lab, out / f"map_{tag}.png")
            if p is not None:
                figs.append(p)
        figs.append(error_figure(run, lab, out / f"errors_{tag}.png"))
        if run.truth is not None and run.trajectory.covs is not None:
            figs.append(nees_figure(run, lab, out / f"nees_{tag}.png"))
        heading = heading_error_figure(run, lab, out / f"heading_error_{tag}.png")
        if heading is not None:
            figs.append(heading)
        learned = learned_noise_figure(run, lab, out / f"noise_{tag}.png")
        if learned is not None:
            figs.append(learned)
        if (run.run_dir / "consistency.png").is_file():  # the NIS is in the run's files only
            figs.append(out / f"consistency_{tag}.png")
            shutil.copyfile(run.run_dir / "consistency.png", figs[-1])
        figures += figs
        md += [f"### {lab} on {names[run.source]} (`{run.name}`)", ""]
        md += [f"- {note}" for note in run.notes] + ([""] if run.notes else [])
        calibration = calibration_lines(run)
        md += calibration + ([""] if calibration else [])
        md += [f"![{p.stem}]({p.name})\n" for p in figs]
    path = out / "report.md"
    path.write_text("\n".join(md) + "\n")
    return ReportResult(path, figures, rows)
