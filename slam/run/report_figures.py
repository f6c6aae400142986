"""The figures of ``sonarslam report`` (:mod:`sonarslam.slam.run.report`): trajectories and their error in
time, the ATE per time segment, each run's map, error bounds and NEES.

The reference of a simulated run is the simulator's truth (its GPS is simulated, noisy); of a
real run, the GPS fixes.
"""

from __future__ import annotations

import math
import shutil
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from sonarslam.features.projection import project_beams
from sonarslam.slam.eval.ate import ate_errors, rigid_fit, truth_errors
from sonarslam.slam.eval.consistency import chi2_band, nees_series, pose_errors
from sonarslam.slam.eval.truth import (
    calibration_sigmas,
    true_calibration,
    truth_heading_error,
    truth_walls,
)
from sonarslam.slam.io.maps import MapLayers, landmark_layers, plot_map
from sonarslam.slam.io.plots import (
    plot_error_bounds,
    plot_heading_error,
    plot_learned_noise,
    plot_nees,
    plot_segment_ate,
    plot_trajectories,
)
from sonarslam.slam.io.states import (
    HEADING_ERROR_FILE,
    NOISE_FILE,
    read_heading_error,
    read_learned_noise,
)
from sonarslam.slam.io.trajectory import FloatArray, Trajectory, cov_file
from sonarslam.slam.run.presets import map_min_intensity
from sonarslam.slam.run.report_data import RunData

__all__ = [
    "SEGMENT_S",
    "SegmentTable",
    "run_errors",
    "segment_table",
    "error_figure",
    "nees_figure",
    "heading_error_figure",
    "learned_noise_figure",
    "calibration_lines",
    "map_figure",
    "trajectory_figure",
    "segment_figure",
]

#: Length of the time segments of the per-segment ATE (s).
SEGMENT_S = 300.0


def run_errors(run: RunData) -> tuple[FloatArray, FloatArray, str]:
    """Times (Unix s) and position errors (m) of a run against its reference, and its name
    (``"truth"``, ``"GPS"``): the ATE's own errors (:mod:`sonarslam.slam.eval.ate`)."""
    if run.truth is not None:
        t, e = truth_errors(run.trajectory, run.truth)
        return t, e, "truth"
    if run.dataset is not None and run.dataset.gps is not None:
        t, e = ate_errors(run.trajectory, run.dataset.gps)
        return t, e, "GPS"
    gps = run.gps
    return (
        gps.t_s,
        np.hypot(*(run.trajectory.poses(gps.t_s)[:, :2] - gps.poses_wTb[:, :2]).T),
        "GPS",
    )


def _walls(run: RunData) -> FloatArray | None:
    ds = run.dataset
    return truth_walls(ds) if ds is not None and ds.truth and "walls_m" in ds.truth else None


def _sigmas_at(trajectory: Trajectory, t_s: FloatArray) -> FloatArray | None:
    if trajectory.covs is None:
        return None
    i = np.clip(np.searchsorted(trajectory.t_s, t_s, side="right") - 1, 0, trajectory.t_s.size - 1)
    return np.sqrt(np.clip(np.diagonal(trajectory.covs[i], axis1=1, axis2=2), 0.0, None))


def band_model(run: RunData, label: str) -> str:
    """Which covariance a run's error band is: the bands of dead reckoning and of a closed loop
    with an AHRS-bias state are different models (the issue of comparing their widths)."""
    sd = run.metrics.get("state_ahrs_bias_sd_deg")
    if sd is not None:
        return (
            f"band: 3σ of the {label} covariance, with its AHRS-bias state (sd {sd:.1f}° at the"
            " end), a constant heading error no landmark observes: it grows with the distance"
            " from the start"
        )
    if run.backend == "dr":
        return "band: 3σ of dead reckoning's covariance: DVL and AHRS noise, no AHRS-bias state"
    return f"band: 3σ of the {label} covariance"


def _aligned_errors(est_xy: FloatArray, ref_xy: FloatArray) -> FloatArray | None:
    """East and North error (m) after the rigid (Umeyama, no scale) alignment of the estimate's
    positions onto the reference's: the error without the start fix and a constant heading."""
    if est_xy.shape[0] < 3:
        return None
    return np.asarray(rigid_fit(est_xy, ref_xy) - ref_xy, dtype=np.float64)


def error_figure(run: RunData, label: str, out: Path) -> Path:
    """East, North (and heading, against the truth) errors in time with the 3-sigma bounds of
    the run's own covariance, saying which model it is (the GPS sigma added against GPS), and
    the error after a rigid alignment, which compares like with like between runs."""
    if run.truth is not None:
        t = run.gps.t_s
        e = pose_errors(run.trajectory, run.truth, t)
        ref_name, ref_sigma_m = "truth", 0.0
        ref_xy = run.truth.poses(t)[:, :2]
    else:
        if run.dataset is not None and run.dataset.gps is not None:
            gps = run.dataset.gps
            t0, t1 = run.trajectory.span_s
            inside = (gps.t >= t0) & (gps.t <= t1)
            t, xy = gps.t[inside], gps.en_m[inside]
            ref_sigma_m = float(run.dataset.config.noise.gps_sigma_m)
        else:
            t, xy, ref_sigma_m = run.gps.t_s, run.gps.poses_wTb[:, :2], 0.0
        e = run.trajectory.poses(t)[:, :2] - xy
        ref_name, ref_xy = "GPS", xy
    s = _sigmas_at(run.trajectory, t)
    if s is not None:
        s = s[:, : e.shape[1]].copy()
        s[:, :2] = np.sqrt(s[:, :2] ** 2 + ref_sigma_m**2)
    gps_note = f", bounds include the GPS sigma {ref_sigma_m:g} m" if ref_sigma_m > 0 else ""
    title = (
        f"{run.dataset_name}: {label} against {ref_name}{gps_note}"
        + ("" if s is not None else f" (no {cov_file(run.stem)}: no bounds)")
        + f"\n{band_model(run, label)}"
        + "\nbands of different back ends are different models; the error after a rigid"
        " alignment compares runs alike"
    )
    aligned = _aligned_errors(run.trajectory.poses(t)[:, :2], ref_xy)
    return plot_error_bounds(out, t, e, s, title, ref_name, "±3σ, own covariance", aligned)


def heading_error_figure(run: RunData, label: str, out: Path) -> Path | None:
    """The run's AHRS heading error track (``heading_error.csv``) with its 2-sigma band, and the
    simulator's true error; None when the run has no track (a constant bias)."""
    path = run.run_dir / HEADING_ERROR_FILE
    if not path.exists():
        return None
    t, b, sd = read_heading_error(path)
    truth = truth_heading_error(run.dataset) if run.dataset is not None else None
    title = f"{run.dataset_name}: {label}, AHRS heading error b (the AHRS measures yaw + b)"
    return plot_heading_error(out, t, b, sd, title, truth)


def learned_noise_figure(run: RunData, label: str, out: Path) -> Path | None:
    """The noise the run learned over time (``noise.csv``, ``learn_noise``); None when it
    learned none."""
    path = run.run_dir / NOISE_FILE
    if not path.exists():
        return None
    t, values = read_learned_noise(path)
    title = f"{run.dataset_name}: {label}, the noise learned from its innovations"
    return plot_learned_noise(out, t, values, title)


#: The calibration estimates of ``metrics.json``: (label, key, its sd's key, unit).
_CALIBRATION = (
    ("sonar mounting x", "state_sonar_x_m", "state_sonar_x_sd_m", "m"),
    ("sonar mounting y", "state_sonar_y_m", "state_sonar_y_sd_m", "m"),
    ("sonar mounting yaw", "state_sonar_yaw_deg", "state_sonar_yaw_sd_deg", "deg"),
    ("sonar range scale", "state_sonar_range_scale", "state_sonar_range_scale_sd", ""),
    ("DVL misalignment", "state_misalignment_deg", "state_misalignment_sd_deg", "deg"),
    ("AHRS heading error (end)", "state_ahrs_bias_deg", "state_ahrs_bias_sd_deg", "deg"),
    ("DVL scale k", "state_dvl_scale", "state_dvl_scale_sd", ""),
)


def _decimals(sd: float) -> int:
    """Decimals that show ``sd`` to two significant figures (0 from 10 up, 3 for 0.012)."""
    if not (math.isfinite(sd) and sd > 0.0):
        return 6
    return max(0, 1 - math.floor(math.log10(sd)))


def _fixed(v: float, decimals: int) -> str:
    """``v`` to ``decimals``, without the sign of a value that rounds to zero."""
    text = f"{v:.{decimals}f}"
    return text[1:] if text.startswith("-") and float(text) == 0.0 else text


def calibration_lines(run: RunData) -> list[str]:
    """One Markdown list item per calibration estimate of the run's ``metrics.json``, with its
    sd, and on simulated data the truth and the error in sigmas
    (:func:`sonarslam.slam.eval.truth.true_calibration`)."""
    m = run.metrics
    truth = {}
    if run.dataset is not None:
        truth = true_calibration(run.dataset, run.trajectory.span_s[1])
    lines = []
    for label, key, sd, unit in _CALIBRATION:
        if key not in m or sd not in m:
            continue
        d = _decimals(float(m[sd]))
        text = f"- {label}: {_fixed(m[key], d)} ± {_fixed(m[sd], d)} {unit} (1σ)"
        text = text.replace("  ", " ")
        if key in truth:
            text += (
                f"; truth {_fixed(truth[key], d + 1)}, error"
                f" {calibration_sigmas(m, truth, key):+.1f}σ"
            )
        in_map = truth.get("dvl_scale_in_sonar_map")
        untold = key == "state_dvl_scale" and "state_sonar_range_scale" not in m
        if untold and in_map is not None and in_map != truth[key]:
            z_map = calibration_sigmas(m, truth, key, "dvl_scale_in_sonar_map")
            text += (
                f"; the sonar's range scale {truth['state_sonar_range_scale']:.6g}, not"
                f" estimated, puts it at {in_map:.6g} in the sonar's map ({z_map:+.1f}σ)"
            )
        lines.append(text)
    corr = m.get("state_sonar_yaw_misalignment_corr")
    if corr is not None:
        lines.append(
            f"- correlation of the sonar mounting's yaw with the DVL misalignment: {corr:+.2f}"
            " (the data see their difference far better than either)"
        )
    for label, key, unit in _LEARNED:
        if f"{key}_final" in m:
            lines.append(
                f"- learned {label}: {m[f'{key}_final']:.3g} at the end, at most"
                f" {m[f'{key}_max']:.3g}{unit}"
            )
    return lines


#: The learned noise of ``metrics.json`` (``noise_*_{final,max}``): (label, key, unit).
_LEARNED = (
    ("heading walk", "noise_heading_walk_deg_per_sqrt_s", " deg/√s"),
    ("DVL scale walk", "noise_dvl_scale_walk_per_sqrt_s", " /√s"),
    ("line covariance factor", "noise_line_scale", ""),
    ("revisit covariance factor", "noise_scan_scale", ""),
)


def nees_figure(run: RunData, label: str, out: Path) -> Path:
    """Pose and position NEES against the simulator's truth, with their chi2 bands."""
    assert run.truth is not None
    series = {}
    for comp in ("pose", "position"):
        s = nees_series(run.trajectory, run.truth, comp)
        series[f"{comp} NEES"] = (s.t_s, s.nees, s.dof, chi2_band(s.dof))
    return plot_nees(
        out, series, f"{run.dataset_name}: {label}, NEES against the simulator's truth"
    )


def map_figure(run: RunData, label: str, out: Path) -> Path | None:
    """The run's landmarks with their 95 % bands over the bins projected with its trajectory,
    its reference (GPS or the truth) and the true walls; the run's own ``map.png`` when the
    dataset is gone."""
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
    segments, bands = landmark_layers(run.landmarks, points)
    ref = {"truth": run.truth.clip(t0, t1)} if run.truth is not None else {"gps": run.gps}
    layers = MapLayers(
        points,
        {**ref, run.backend: run.trajectory},
        segments,
        bands,
        _walls(run),
        segment_ids=[lm["id"] for lm in run.landmarks],
    )
    return plot_map(
        out,
        layers,
        f"{run.dataset_name}: {label}, {len(segments)} landmarks (id, 95 % band) on"
        " the bins projected with its trajectory",
    )


def trajectory_figure(runs: list[RunData], labels: dict[str, str], out: Path) -> Path:
    """The runs of one dataset against their reference, in the plane and in time."""
    longest = max(runs, key=lambda r: r.gps.t_s.size)
    ref_name = "truth" if longest.truth is not None else "gps"
    reference = longest.truth if longest.truth is not None else longest.gps
    trajectories: dict[str, Trajectory] = {ref_name: reference.clip(*longest.trajectory.span_s)}
    errors = {}
    for run in runs:
        lab = labels[str(run.run_dir)]
        trajectories[lab] = run.trajectory
        t, e, _ = run_errors(run)
        errors[lab] = (t, e)
    span = longest.metrics.get("sonar_span_s")
    name = "the truth" if ref_name == "truth" else "GPS"
    return plot_trajectories(
        out,
        trajectories,
        errors,
        f"{runs[0].dataset_name}: trajectories against {name}",
        name,
        None if span is None else (float(span[0]), float(span[1])),
        _walls(longest),
    )


@dataclass(frozen=True)
class SegmentTable:
    """The ATE per time segment of the runs of one dataset.

    Attributes
    ----------
    edges_s : ndarray, shape (K + 1,)
        Segment edges, seconds since the first reference time of the runs.
    mean_m, max_m : dict of str to ndarray, shape (K,)
        Per run label: the mean and max error of each segment (NaN: no fix there).
    reference : str
    sonar_end_s : float or None
        When the sonar stops, seconds since the same start (None: it runs to the end).
    segment_s : float
        The segments' length (the last one ends with the data).
    """

    edges_s: FloatArray
    mean_m: dict[str, FloatArray]
    max_m: dict[str, FloatArray]
    reference: str
    sonar_end_s: float | None
    segment_s: float = SEGMENT_S


def segment_table(
    runs: list[RunData], labels: dict[str, str], segment_s: float = SEGMENT_S
) -> SegmentTable:
    """Mean and max error per ``segment_s`` of each run of one dataset (:func:`run_errors`)."""
    errs = {labels[str(r.run_dir)]: run_errors(r) for r in runs}
    t0 = min(float(t[0]) for t, _, _ in errs.values() if t.size)
    t1 = max(float(t[-1]) for t, _, _ in errs.values() if t.size)
    # whole segments, the last one ending with the data
    edges = np.append(np.arange(0.0, t1 - t0, segment_s), t1 - t0)
    if edges.size < 2 or edges[-1] <= edges[-2]:
        edges = np.array([0.0, max(t1 - t0, 1e-9)])
    mean_m, max_m = {}, {}
    for lab, (t, e, _) in errs.items():
        k = np.clip(np.searchsorted(edges, t - t0, side="right") - 1, 0, edges.size - 2)
        counts = np.bincount(k, minlength=edges.size - 1)
        sums = np.bincount(k, weights=e, minlength=edges.size - 1)
        with np.errstate(invalid="ignore", divide="ignore"):
            mean_m[lab] = np.where(counts > 0, sums / counts, np.nan)
        peak = np.full(edges.size - 1, np.nan)
        np.fmax.at(peak, k, e)
        max_m[lab] = peak
    span = runs[0].metrics.get("sonar_span_s")
    sonar_end = None if span is None else float(span[1]) - t0
    if sonar_end is not None and sonar_end >= t1 - t0 - 1.0:
        sonar_end = None  # the sonar runs to the end
    reference = next(iter(errs.values()))[2]
    return SegmentTable(edges, mean_m, max_m, reference, sonar_end, segment_s)


def segment_figure(table: SegmentTable, dataset_name: str, out: Path) -> Path:
    """:func:`sonarslam.slam.io.plots.plot_segment_ate` of a :class:`SegmentTable`."""
    stats = {lab: (table.mean_m[lab], table.max_m[lab]) for lab in table.mean_m}
    return plot_segment_ate(
        out,
        table.edges_s,
        stats,
        f"{dataset_name}: ATE per {table.segment_s:.0f} s against {table.reference}",
        table.reference,
        table.sonar_end_s,
    )
