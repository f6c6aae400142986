"""A side-by-side report of run directories (``sonarslam report DIR... --out OUT``).

Reads what :func:`slam.run.run.run` wrote in each directory (``metrics.json``,
``trajectory.tum``, ``ground_truth.tum``, and when present ``trajectory_cov.npz``, ``map.json``),
re-opens the run's dataset when it is still there (``metrics.json``'s ``source``: the GPS fixes,
the sonar beams, the simulator's truth), and writes into ``OUT``:

* ``report.md``: one table of every run beside the published figures on the marina (Mallios et
  al. 2014, Table 2): ATE mean, sd, min, max, rmse by the GPS protocol, the real-time factor,
  evo's APE and RPE per ``rpe_delta_m`` of path (:mod:`slam.eval.consistency`), and the pose NEES of
  simulated runs; then the consistency over the runs of each back end (ANEES) and the figures;
* ``trajectories_<dataset>.png``: the runs of one dataset against GPS, with their ATE in time;
* ``map_<run>.png``: the landmarks' segments with their 95 % bands over the sonar bins projected
  with the run's trajectory (the run's own ``map.png`` when the dataset is gone);
* ``errors_<run>.png``: East, North (and heading, against the truth) errors in time with the
  3-sigma bounds of the trajectory covariances (and of the GPS noise against GPS);
* ``nees_<run>.png``: pose and position NEES in time with their chi2 bands (simulated runs).
"""

from __future__ import annotations

import json
import math
import re
import shutil
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from datasets.errors import DataError
from datasets.source import Dataset, open_dataset
from features.geometry import FloatArray
from features.line import LineFeature
from features.projection import project_beams
from slam.eval.consistency import (
    NeesSeries,
    anees,
    chi2_band,
    mean_nees_band,
    nees_on_grid,
    nees_series,
    pose_errors,
)
from slam.eval.evo_metrics import evo_metrics_of_run
from slam.eval.published import PUBLISHED
from slam.eval.truth import truth_trajectory
from slam.io.plots import (
    plot_error_bounds,
    plot_lines,
    plot_nees,
    plot_trajectories,
    segment_band_world,
)
from slam.io.trajectory import COV_FILE, Trajectory, load_run_trajectory, read_tum
from slam.run.presets import map_min_intensity

__all__ = [
    "DISPLAY_NAMES",
    "RunData",
    "ReportResult",
    "load_run",
    "evaluate_run",
    "landmark_band_world",
    "report",
]


#: Names of the back ends in the table.
DISPLAY_NAMES = {"dr": "dead reckoning", "gps": "GPS + AHRS", "ekf": "EKF-SLAM", "isam2": "iSAM2"}


@dataclass
class RunData:
    """One run directory, read.

    Attributes
    ----------
    run_dir : Path
    metrics : dict
        ``metrics.json``.
    trajectory : Trajectory
        ``trajectory.tum``, with the covariances of ``trajectory_cov.npz`` when present.
    ground_truth : Trajectory
        ``ground_truth.tum`` (GPS with the AHRS heading).
    landmarks : list of dict or None
        ``map.json``'s landmarks (closed loops).
    dataset : Dataset or None
        The run's dataset, when its ``source`` can still be opened.
    truth : Trajectory or None
        The simulator's truth (simulated datasets).
    """

    run_dir: Path
    metrics: dict[str, Any]
    trajectory: Trajectory
    ground_truth: Trajectory
    landmarks: list[dict[str, Any]] | None = None
    dataset: Dataset | None = None
    truth: Trajectory | None = None
    notes: list[str] = field(default_factory=list)

    @property
    def backend(self) -> str:
        return str(self.metrics.get("backend", self.run_dir.name))

    @property
    def dataset_name(self) -> str:
        return Path(str(self.metrics.get("source", "unknown"))).name

    @property
    def name(self) -> str:
        return self.run_dir.name


def load_run(run_dir: str | Path, open_source: bool = True) -> RunData:
    """Read a run directory; open its dataset unless ``open_source`` is False (or it is gone)."""
    run = Path(run_dir)
    for name in ("metrics.json", "trajectory.tum", "ground_truth.tum"):
        if not (run / name).is_file():
            raise FileNotFoundError(f"{run}: no {name} (not a run directory of sonarslam run)")
    metrics = json.loads((run / "metrics.json").read_text())
    data = RunData(run, metrics, load_run_trajectory(run), read_tum(run / "ground_truth.tum"))
    if (run / "map.json").is_file():
        data.landmarks = json.loads((run / "map.json").read_text()).get("landmarks", [])
    if data.trajectory.covs is None:
        data.notes.append(f"no {COV_FILE}: no covariance bounds nor NEES")
    source = metrics.get("source")
    if open_source and source:
        try:
            data.dataset = open_dataset(source)
        except (DataError, OSError) as exc:
            data.notes.append(f"dataset not opened ({exc}): no reprojected map, GPS from the TUM")
    if data.dataset is not None and data.dataset.truth is not None:
        data.truth = truth_trajectory(data.dataset)
    return data


def evaluate_run(run: RunData, rpe_delta_m: float = 10.0, align: bool = False) -> dict[str, Any]:
    """evo's APE/RPE on the run's TUM files and, with truth and covariances, the NEES.

    Returns
    -------
    dict
        :func:`slam.eval.consistency.evo_metrics_of_run`'s keys, and ``nees_mean``,
        ``nees_in_band_fraction`` (pose, 3 dof), ``nees_position_mean`` when available.
    """
    out: dict[str, Any] = dict(evo_metrics_of_run(run.run_dir, rpe_delta_m, align=align))
    if run.truth is not None and run.trajectory.covs is not None:
        pose = nees_series(run.trajectory, run.truth, "pose")
        out["nees_mean"] = pose.mean
        out["nees_in_band_fraction"] = pose.in_band_fraction()
        out["nees_position_mean"] = nees_series(run.trajectory, run.truth, "position").mean
    return out


def landmark_band_world(
    landmark: dict[str, Any], confidence: float = 0.95
) -> tuple[FloatArray, FloatArray]:
    """Segment (2, 2) and 95 % band polygon (M, 2) of a ``map.json`` landmark, world (m).

    The landmark's world line ``(rho, theta)`` with its covariance is a line feature seen from
    the world origin, so the band is :func:`slam.io.plots.segment_band_world`'s (exact: the
    envelope of the lines of the confidence ellipse, over the segment).
    """
    ends = np.asarray(landmark["endpoints"], dtype=np.float64)
    feature = LineFeature(
        t=0.0,
        wTr=np.zeros(3),
        rho_m=float(landmark["rho"]),
        theta_rad=float(landmark["theta"]),
        cov=np.asarray(landmark["cov"], dtype=np.float64),
        votes=0,
        endpoints_r=ends,
    )
    return ends, segment_band_world(feature, confidence)


@dataclass
class ReportResult:
    """The report's file, its figures and its table rows."""

    path: Path
    figures: list[Path]
    rows: list[dict[str, Any]]


def _label(run: RunData, runs: list[RunData]) -> str:
    same = [r for r in runs if r.backend == run.backend and r.dataset_name == run.dataset_name]
    return run.backend if len(same) == 1 else f"{run.backend} ({run.name})"


def _safe(name: str) -> str:
    return re.sub(r"[^A-Za-z0-9_.-]+", "_", name)


def _reference(run: RunData) -> tuple[FloatArray, FloatArray, str, float]:
    """Times and positions of the reference of the error figure, its name, its sigma (m)."""
    if run.truth is not None:
        t = run.ground_truth.t_s
        return t, run.truth.poses(t), "truth", 0.0
    if run.dataset is not None and run.dataset.gps is not None:
        gps = run.dataset.gps
        t0, t1 = run.trajectory.span_s
        inside = (gps.t >= t0) & (gps.t <= t1)
        xy = gps.en_m[inside]
        sigma = float(run.dataset.config.noise.gps_sigma_m)
        return gps.t[inside], np.column_stack([xy, np.zeros(len(xy))]), "GPS", sigma
    return run.ground_truth.t_s, run.ground_truth.poses_wTb, "GPS (ground_truth.tum)", 0.0


def _sigmas_at(trajectory: Trajectory, t_s: FloatArray) -> FloatArray | None:
    if trajectory.covs is None:
        return None
    i = np.clip(np.searchsorted(trajectory.t_s, t_s, side="right") - 1, 0, trajectory.t_s.size - 1)
    return np.sqrt(np.clip(np.diagonal(trajectory.covs[i], axis1=1, axis2=2), 0.0, None))


def _error_figure(run: RunData, label: str, out: Path) -> Path:
    t, ref, ref_name, ref_sigma_m = _reference(run)
    if ref_name == "truth":
        e = pose_errors(run.trajectory, Trajectory(t, ref), t)
        n = 3
    else:
        e = run.trajectory.poses(t)[:, :2] - ref[:, :2]
        n = 2
    s = _sigmas_at(run.trajectory, t)
    if s is not None:
        s = s[:, :n].copy()
        s[:, :2] = np.sqrt(s[:, :2] ** 2 + ref_sigma_m**2)
    gps_note = f", bounds include the GPS sigma {ref_sigma_m:g} m" if ref_sigma_m > 0 else ""
    title = f"{run.dataset_name}: {label} against {ref_name}{gps_note}" + (
        "" if s is not None else f" (no {COV_FILE}: no bounds)"
    )
    return plot_error_bounds(out, t, e, s, title, ref_name)


def _nees_figure(run: RunData, label: str, out: Path) -> Path:
    assert run.truth is not None
    series = {}
    for comp in ("pose", "position"):
        s = nees_series(run.trajectory, run.truth, comp)
        series[f"{comp} NEES"] = (s.t_s, s.nees, s.dof, chi2_band(s.dof))
    return plot_nees(
        out, series, f"{run.dataset_name}: {label}, NEES against the simulator's truth"
    )


def _map_figure(run: RunData, label: str, out: Path) -> Path | None:
    assert run.landmarks is not None
    if run.dataset is None:
        if (run.run_dir / "map.png").is_file():
            shutil.copyfile(run.run_dir / "map.png", out)
            return out
        return None
    ds = run.dataset
    t0, t1 = run.trajectory.span_s
    beams = [b for b in ds.nav_beams() if t0 <= b.t <= t1]
    points, _ = project_beams(
        beams, ds.config.sonar, ds.config.sonar_mounting, run.trajectory, map_min_intensity(beams)
    )
    segs, bands = [], []
    for lm in run.landmarks:
        seg, band = landmark_band_world(lm)
        segs.append(seg)
        bands.append(band)
    return plot_lines(
        out,
        points,
        segs,
        bands,
        f"{run.dataset_name}: {label}, {len(segs)} landmarks with 95 % bands over the bins "
        "projected with its trajectory",
        {label: run.trajectory},
    )


def _trajectory_figure(runs: list[RunData], labels: dict[str, str], out: Path) -> Path:
    longest = max(runs, key=lambda r: r.ground_truth.t_s.size)
    trajectories: dict[str, Trajectory] = {"gps": longest.ground_truth}
    errors = {}
    for run in runs:
        lab = labels[str(run.run_dir)]
        trajectories[lab] = run.trajectory
        t, ref, _, _ = _gps_reference(run)
        errors[lab] = (t, np.hypot(*(run.trajectory.poses(t)[:, :2] - ref[:, :2]).T))
    return plot_trajectories(
        out,
        trajectories,
        errors,
        f"{runs[0].dataset_name}: trajectories against GPS (ATE against the GPS fixes, right)",
    )


def _gps_reference(run: RunData) -> tuple[FloatArray, FloatArray, str, float]:
    if run.dataset is not None and run.dataset.gps is not None:
        truthless = RunData(run.run_dir, run.metrics, run.trajectory, run.ground_truth)
        truthless.dataset = run.dataset
        return _reference(truthless)
    return run.ground_truth.t_s, run.ground_truth.poses_wTb, "GPS (ground_truth.tum)", 0.0


def _fmt(v: Any, digits: int = 2) -> str:
    if v is None or (isinstance(v, float) and not math.isfinite(v)):
        return ""
    if isinstance(v, int | np.integer):
        return f"{int(v):d}"
    if isinstance(v, float) and abs(v) >= 1000:
        return f"{v:,.0f}"
    return f"{v:.{digits}f}"


_COLUMNS = [
    ("method", "method"),
    ("run", "run"),
    ("dataset", "dataset"),
    ("ate_mean_m", "ATE mean (m)"),
    ("ate_sd_m", "sd"),
    ("ate_min_m", "min"),
    ("ate_max_m", "max"),
    ("ate_rmse_m", "rmse"),
    ("ate_n", "fixes"),
    ("realtime_factor", "real-time factor"),
    ("evo_ape_rmse_m", "evo APE rmse (m)"),
    ("evo_ape_mean_m", "evo APE mean"),
    ("evo_rpe_rmse_m", "evo RPE rmse (m)"),
    ("evo_rpe_mean_m", "evo RPE mean"),
    ("nees_mean", "pose NEES mean (3 dof)"),
    ("nees_in_band_fraction", "NEES in 95 % band"),
]


def _table(rows: list[dict[str, Any]]) -> list[str]:
    lines = [
        "| " + " | ".join(h for _, h in _COLUMNS) + " |",
        "|"
        + "|".join("---" if k in ("method", "run", "dataset") else "---:" for k, _ in _COLUMNS)
        + "|",
    ]
    for r in rows:
        cells = []
        for k, _ in _COLUMNS:
            v = r.get(k)
            if k == "realtime_factor":
                cells.append("" if v is None else f"{_fmt(float(v), 0)}x")
            elif k == "nees_in_band_fraction":
                cells.append("" if v is None else f"{100 * v:.0f} %")
            else:
                cells.append(v if isinstance(v, str) else _fmt(v))
        lines.append("| " + " | ".join(cells) + " |")
    return lines


def _consistency(runs: list[RunData], period_s: float = 1.0) -> list[str]:
    """ANEES per back end over the simulated runs given (one time grid from each start)."""
    lines: list[str] = []
    by_backend: dict[str, list[NeesSeries]] = {}
    starts: dict[str, list[float]] = {}
    for run in runs:
        if run.truth is None or run.trajectory.covs is None:
            continue
        by_backend.setdefault(run.backend, []).append(nees_series(run.trajectory, run.truth))
        starts.setdefault(run.backend, []).append(run.trajectory.t_s[0])
    if not by_backend:
        return lines
    lines += [
        "## Consistency over the simulated runs",
        "",
        "Pose NEES (3 dof) of each run on a 1 s grid from its start; ANEES at each time is the "
        "mean over the runs, inside the two-sided 95 % band `chi2.ppf([0.025, 0.975], 3 N) / N` "
        "when consistent.",
        "",
        "| back end | runs N | ANEES (time mean) | 95 % band for N | times with ANEES in band |",
        "|---|---:|---:|---:|---:|",
    ]
    for backend, series in by_backend.items():
        span = max(float(s.t_s[-1] - s.t_s[0]) for s in series if s.t_s.size)
        grid = np.arange(0.0, span + 1e-9, period_s)
        X = np.array(
            [nees_on_grid(s, t0, grid) for s, t0 in zip(series, starts[backend], strict=True)]
        )
        res = anees(X, 3, grid)
        lo, hi = mean_nees_band(len(series), 3)
        lines.append(
            f"| {DISPLAY_NAMES.get(backend, backend)} | {len(series)} | {res.mean:.2f} | "
            f"{lo:.2f} - {hi:.2f} | {100 * res.in_band_fraction:.0f} % |"
        )
    return lines + [""]


def _rows(runs: list[RunData], rpe_delta_m: float, align: bool) -> list[dict[str, Any]]:
    """The table's rows: every run, then the published ones."""
    rows: list[dict[str, Any]] = []
    for run in runs:
        ev = evaluate_run(run, rpe_delta_m, align)
        m = run.metrics
        row = {
            "method": DISPLAY_NAMES.get(run.backend, run.backend) + " (ours)",
            "run": run.name,
            "dataset": run.dataset_name,
            **{k: m.get(k) for k in ("ate_mean_m", "ate_sd_m", "ate_min_m", "ate_max_m")},
            **{k: m.get(k) for k in ("ate_rmse_m", "ate_n", "realtime_factor")},
            **ev,
            "evo_rpe_rmse_m": ev.get(f"evo_rpe_{rpe_delta_m:g}m_rmse_m"),
            "evo_rpe_mean_m": ev.get(f"evo_rpe_{rpe_delta_m:g}m_mean_m"),
        }
        rows.append(row)
    for r in PUBLISHED:
        rows.append(
            {
                "method": r["method"],
                "run": "published (Mallios 2014, Table 2)",
                "dataset": "marina",
                "ate_mean_m": r["mean"],
                "ate_sd_m": r["sd"],
                "ate_min_m": r["min"],
                "ate_max_m": r["max"],
            }
        )
    return rows


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
    runs = [load_run(d, open_source=open_sources) for d in run_dirs]
    labels = {str(r.run_dir): _label(r, runs) for r in runs}
    rows = _rows(runs, rpe_delta_m, align)
    figures: list[Path] = []
    # figures
    by_dataset: dict[str, list[RunData]] = {}
    for run in runs:
        by_dataset.setdefault(run.dataset_name, []).append(run)
    traj_figs = {
        name: _trajectory_figure(group, labels, out / f"trajectories_{_safe(name)}.png")
        for name, group in by_dataset.items()
    }
    figures += list(traj_figs.values())
    per_run: dict[str, list[Path]] = {}
    for run in runs:
        lab = labels[str(run.run_dir)]
        tag = _safe(run.name)
        figs = []
        if run.landmarks is not None:
            p = _map_figure(run, lab, out / f"map_{tag}.png")
            if p is not None:
                figs.append(p)
        figs.append(_error_figure(run, lab, out / f"errors_{tag}.png"))
        if run.truth is not None and run.trajectory.covs is not None:
            figs.append(_nees_figure(run, lab, out / f"nees_{tag}.png"))
        per_run[str(run.run_dir)] = figs
        figures += figs
    # the markdown
    md = [
        "# sonarslam report",
        "",
        f"Runs: {', '.join(f'`{r.run_dir}`' for r in runs)}.",
        "",
        "ATE (m) by the protocol of Mallios et al. 2014: at every GPS fix inside the run, the "
        "distance to the estimate interpolated there, no alignment (sd with ddof 1). evo's APE "
        f"is on `trajectory.tum` against `ground_truth.tum` (translation, "
        f"{'Umeyama-aligned' if align else 'no alignment'}, evo's interpolating association; "
        "its sd has ddof 0); evo's RPE is the translation error of the relative motion over "
        f"{rpe_delta_m:g} m of path. The published rows are on the real marina only.",
        "",
        *_table(rows),
        "",
        *_consistency(runs),
        "## Figures",
        "",
    ]
    for name, p in traj_figs.items():
        md += [f"### {name}: trajectories against GPS", "", f"![{p.stem}]({p.name})", ""]
    for run in runs:
        md += [f"### {labels[str(run.run_dir)]} on {run.dataset_name} (`{run.name}`)", ""]
        md += [f"- {note}" for note in run.notes] + ([""] if run.notes else [])
        md += [f"![{p.stem}]({p.name})\n" for p in per_run[str(run.run_dir)]]
    path = out / "report.md"
    path.write_text("\n".join(md) + "\n")
    return ReportResult(path, figures, rows)
