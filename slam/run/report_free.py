"""The report's section for runs without GPS: their GPS-free figures side by side.

A run without GPS has no ATE; ``sonarslam run`` measured instead the loop-closure error of its
estimate and of dead reckoning at the loops stated (``--loop``) and found
(:mod:`sonarslam.slam.eval.loops`), and the map's entropy; on simulated data also the ATE
against the truth (as it is and rigidly aligned) and the pose NEES. This section tables them
per dataset, lists each run's health verdict (:mod:`sonarslam.slam.eval.health`, GPS-free) and
its odometry check (dead reckoning's motion against the sonar's), and draws, per dataset, the runs'
trajectories with their loops (each loop a segment between the estimate's positions at its two
times; the loops are the first run's) beside each run's own ``report.png`` and ``map.png``.
"""

from __future__ import annotations

import json
import math
import shutil
from pathlib import Path
from typing import Any

from matplotlib.figure import Figure

from sonarslam.slam.eval.consistency import nees_series
from sonarslam.slam.io.trajectory import (
    GPS_FILE,
    TRUTH_FILE,
    Trajectory,
    load_run_trajectory,
    read_tum,
    trajectory_stem,
)
from sonarslam.slam.run.report_data import safe_name, source_labels
from sonarslam.slam.run.run import odometry_line

__all__ = ["is_gps_free", "GpsFreeRun", "load_gps_free", "gps_free_section"]

#: The section's table: (metrics.json key, header).
COLUMNS = [
    ("run", "run"),
    ("backend", "back end"),
    ("loops_stated", "loops stated"),
    ("loops_found", "loops found"),
    ("loop_error_mean_m", "loop error: mean (m)"),
    ("loop_error_max_m", "max"),
    ("loop_reference_sigma_m", "references' 1σ (m)"),
    ("loop_error_dr_mean_m", "dead reckoning: mean (m)"),
    ("loop_error_dr_max_m", "max"),
    ("map_entropy_nats", "map entropy (nats)"),
    ("ate_truth_mean_m", "vs truth: ATE mean (m)"),
    ("ate_truth_aligned_mean_m", "aligned mean"),
    ("nees_pose_mean", "pose NEES mean (3 dof)"),
    ("nees_pose_in_band_fraction", "NEES in 95 % band"),
]


def is_gps_free(run_dir: str | Path) -> bool:
    """A run directory without ``gps.tum`` nor an ATE against GPS."""
    run = Path(run_dir)
    try:
        metrics = json.loads((run / "metrics.json").read_text())
    except (OSError, ValueError):
        return False  # not a run directory: the GPS path's loader says so
    return not (run / GPS_FILE).is_file() and "ate_mean_m" not in metrics


class GpsFreeRun:
    """A run directory without GPS: its metrics and trajectory (``<backend>.tum``)."""

    def __init__(self, run_dir: Path, metrics: dict[str, Any], trajectory: Trajectory) -> None:
        self.run_dir = run_dir
        self.metrics = metrics
        self.trajectory = trajectory

    @property
    def name(self) -> str:
        return self.run_dir.name

    @property
    def source(self) -> str:
        """The run's dataset as ``metrics.json`` names it (its path)."""
        return str(self.metrics.get("source", "unknown"))


def load_gps_free(run_dir: str | Path) -> GpsFreeRun:
    """Read a run directory without GPS (``metrics.json`` and ``<backend>.tum``)."""
    run = Path(run_dir)
    metrics = json.loads((run / "metrics.json").read_text())
    backend = str(metrics.get("backend", ""))
    stem = trajectory_stem(backend)
    tum = run / f"{stem}.tum"
    if not tum.is_file():
        raise FileNotFoundError(f"{run}: no {tum.name} (not a run directory of sonarslam run)")
    trajectory = load_run_trajectory(run, stem)
    if (
        "nees_pose_mean" not in metrics
        and (run / TRUTH_FILE).is_file()
        and trajectory.covs is not None
    ):
        # a run written before metrics.json held the NEES: from its truth.tum and covariances
        pose = nees_series(trajectory, read_tum(run / TRUTH_FILE), "pose")
        metrics = {
            **metrics,
            "nees_pose_mean": pose.mean,
            "nees_pose_in_band_fraction": pose.in_band_fraction(),
        }
    return GpsFreeRun(run, metrics, trajectory)


def _fmt(v: Any, key: str = "") -> str:
    if v is None or (isinstance(v, float) and not math.isfinite(v)):
        return ""
    if key.endswith("_fraction"):
        return f"{100 * v:.0f} %"
    if isinstance(v, float):
        return f"{v:.2f}"
    return str(v)


def _run_lines(run: GpsFreeRun) -> list[str]:
    """The run's health verdict and odometry check, as its terminal printed them."""
    m = run.metrics
    lines = []
    if isinstance(m.get("health_line"), str):
        lines.append(f"- `{run.name}`: {m['health_line']}")
    odometry = odometry_line(m)
    if odometry:
        lines.append(f"- `{run.name}`: {odometry}")
    return lines


def _figure(dataset: str, runs: list[GpsFreeRun], path: Path) -> Path:
    fig = Figure(figsize=(7, 6), dpi=110, layout="constrained")
    ax = fig.subplots()
    for r in runs:
        xy = r.trajectory.poses_wTb[:, :2]
        ax.plot(xy[:, 0], xy[:, 1], lw=1, label=f"{r.metrics.get('backend')} ({r.name})")
    first = runs[0]
    for loop in first.metrics.get("loops", []):
        p = first.trajectory.poses([loop["t0_s"], loop["t1_s"]])
        style = "k-" if loop["how"] == "found" else "r--"
        ax.plot(p[:, 0], p[:, 1], style, lw=1.5)
        ax.plot(p[:, 0], p[:, 1], "ko", ms=3)
    ax.set_aspect("equal")
    ax.set_xlabel("East (m)")
    ax.set_ylabel("North (m)")
    ax.set_title(f"{dataset}: no GPS; loops (black found, red dashed stated) of {first.name}")
    ax.legend(fontsize=7)
    fig.savefig(path)
    return path


def _reference_groups(runs: list[GpsFreeRun]) -> list[list[str]]:
    """The runs' names grouped by the loops they were judged at: their times and references
    (``metrics.json`` ``loops``: ``t0_s``, ``t1_s``, ``t0Tt1``, to a micrometre and a
    microradian), in the runs' order."""
    groups: dict[tuple[Any, ...], list[str]] = {}
    for r in runs:
        key = tuple(
            (
                round(float(loop["t0_s"]), 6),
                round(float(loop["t1_s"]), 6),
                *(round(float(v), 6) for v in loop.get("t0Tt1") or ()),
            )
            for loop in r.metrics.get("loops", [])
        )
        groups.setdefault(key, []).append(r.name)
    return list(groups.values())


def gps_free_section(
    runs: list[GpsFreeRun], out: Path
) -> tuple[list[str], list[Path], list[dict[str, Any]]]:
    """The Markdown lines, the figures and the table rows of the runs without GPS."""
    if not runs:
        return [], [], []
    md = [
        "## Runs without GPS",
        "",
        "No ATE: the loop-closure error (the distance between the estimate's relative position"
        " at a loop's two times and the loop's own: zero where the user stated one place,"
        " `--loop`; the registration of the two times' sonar scans where it was found, a return"
        " of dead reckoning within `loop_radius_m`, so that every run of a dataset is judged at"
        " the same loops against the same references; slam/eval/loops.py) of each run's"
        " estimate and of dead reckoning at those loops, the references' own 1σ (their"
        " registrations' covariance: a floor under the errors), the map's entropy (lower is"
        " sharper), and against the truth on simulated data (the ATE as it is and rigidly aligned,"
        " the pose NEES: chi2(3) samples when consistent, mean 3, the share inside their two-sided"
        " 95 % band).",
        "",
    ]
    figures: list[Path] = []
    rows: list[dict[str, Any]] = []
    names = source_labels(r.source for r in runs)
    by_dataset: dict[str, list[GpsFreeRun]] = {}
    for r in runs:
        by_dataset.setdefault(names[r.source], []).append(r)
    for dataset, group in by_dataset.items():
        md += [f"### {dataset}", ""]
        md.append("| " + " | ".join(h for _, h in COLUMNS) + " |")
        md.append("|" + "---|" * len(COLUMNS))
        for r in group:
            row = {
                **r.metrics,
                "run": r.name,
                "dataset": dataset,
                "method": r.metrics.get("backend"),
            }
            rows.append(row)
            md.append("| " + " | ".join(_fmt(row.get(k), k) for k, _ in COLUMNS) + " |")
        md.append("")
        shared = _reference_groups(group)
        if len(shared) > 1:
            md += [
                "**These runs are not judged against the same loop references**: a found loop's"
                " reference is a registration of the sonar's scans made with the run's own"
                " calibration (another sonar mounting or range moves it), so the loop errors"
                " rank runs only within a group that shares them: "
                + "; ".join(", ".join(f"`{n}`" for n in names_) for names_ in shared)
                + ". Against a calibration changed between runs (`sonarslam calibrate --write`),"
                " a lower loop error is no evidence.",
                "",
            ]
        checks = [line for r in group for line in _run_lines(r)]
        if checks:
            md += [
                "Health (GPS-free: each run against its own model) and the odometry check (dead"
                " reckoning's motion against the sonar's registrations of nearby scans):",
                "",
                *checks,
                "",
            ]
        fig = _figure(dataset, group, out / f"loops_{safe_name(dataset)}.png")
        figures.append(fig)
        md += [f"![{fig.stem}]({fig.name})", ""]
        for r in group:
            for name in ("report.png", "map.png"):
                if (r.run_dir / name).is_file():
                    copy = out / f"{Path(name).stem}_{r.name}.png"
                    shutil.copyfile(r.run_dir / name, copy)
                    figures.append(copy)
                    md += [f"![{copy.stem}]({copy.name})", ""]
    return md, figures, rows
