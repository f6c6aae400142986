"""The files of a run directory (``sonarslam run --out DIR``; docs/outputs.md's table).

* ``<backend>.tum`` (``dr.tum``, ``ekf.tum``, ``isam2.tum``; ``gps_ahrs.tum`` for the ``gps``
  baseline) and its covariances ``<backend>_cov.npz``; ``gps.tum`` (the GPS fixes inside the
  run with the AHRS heading: the ATE's reference); on simulated data ``truth.tum`` (the true
  poses inside the run); ``metrics.json``, ``config_used.toml`` (the dataset configuration
  used), ``report.png`` (the run's estimates, a factor graph's smoothed and batch ones too,
  beside dead reckoning against the reference), ``consistency.png`` when the trajectory has
  covariances (NEES against the truth or GPS, and a closed loop's NIS, in time with their chi2
  bands: :mod:`sonarslam.slam.run.consistency_figure`).
  Every estimate is written at its own times and, interpolated, at the reference's times inside
  its span (:func:`sonarslam.slam.io.trajectory.with_samples_at`): ``evo_ape tum gps.tum ekf.tum`` pairs
  the same poses as ``metrics.json``'s ATE and prints its figures;
* closed loops also ``map.json`` (the landmarks), ``lines.jsonl`` (every line with the landmark
  it was associated with), ``map.png`` (the landmarks with their 95 % bands over the sonar bins
  projected with the run's trajectory), one ``<backend>_<name>.tum`` per other trajectory of the
  back end (``isam2_smoothed.tum``, ``isam2_batch.tum``) and whatever the back end saves
  (``graph.json``, and its poses and odometry as ``graph.g2o``: :mod:`sonarslam.slam.backends.isam2.g2o`).

Every file is written under a temporary name and renamed when whole (:mod:`sonarslam.slam.io.files`);
``metrics.json`` is strict JSON (null where a figure is undefined).
"""

from __future__ import annotations

import json
from functools import partial
from pathlib import Path
from typing import Any

import numpy as np

from sonarslam.datasets.config import dump_dataset_config
from sonarslam.datasets.source import Dataset
from sonarslam.features.projection import project_beams
from sonarslam.slam.backends.isam2.g2o import graph_json_to_g2o
from sonarslam.slam.backends.registry import BACKENDS
from sonarslam.slam.eval.ate import ate_errors, truth_errors
from sonarslam.slam.eval.truth import truth_trajectory, truth_walls
from sonarslam.slam.io.files import (
    json_safe,
    make_output_dir,
    write_atomic,
    write_files_into,
    write_json,
    write_text,
)
from sonarslam.slam.io.maps import MapLayers, landmark_layers, plot_map
from sonarslam.slam.io.plots import plot_trajectories
from sonarslam.slam.io.trajectory import (
    GPS_FILE,
    TRUTH_FILE,
    Trajectory,
    cov_file,
    trajectory_stem,
    with_samples_at,
    write_trajectory_covariances,
    write_tum,
)
from sonarslam.slam.run.closed_loop import ClosedLoopResult
from sonarslam.slam.run.consistency_figure import CONSISTENCY_FILE, write_consistency_figure
from sonarslam.slam.run.health import nis_streams
from sonarslam.slam.run.presets import map_min_intensity
from sonarslam.slam.run.sources import (
    CLOSED_LOOP_START_ONLY,
    DR_IGNORES,
    dead_reckoning_trajectory,
    gps_ahrs_trajectory,
)

__all__ = ["write_run", "plot_estimates"]


def write_run(
    out: Path,
    dataset: Dataset,
    backend: str,
    trajectory: Trajectory,
    metrics: dict[str, Any],
    closed_loop: ClosedLoopResult | None,
    trajectories: dict[str, Trajectory],
    notes: list[str] | None = None,
) -> list[Path]:
    """Write a run's files into ``out`` (created); returns the files written, in order (what
    was in ``out`` before, another run's files, is not among them). ``notes``: gets a line for
    the terminal about what a file holds (``graph.g2o``'s: what g2o cannot hold)."""
    make_output_dir(out)
    used = dump_dataset_config(dataset.config)
    if backend == "dr":
        used = "".join(f"# ignored by dead reckoning: {key}\n" for key in DR_IGNORES) + used
    elif backend in BACKENDS:  # the closed loops
        used = (
            "".join(
                f"# the start pose's only (the AHRS model: ahrs_white_sigma_deg and"
                f" ahrs_bias_sigma_deg): {key}\n"
                for key in CLOSED_LOOP_START_ONLY
            )
            + used
        )
    files = [write_text(out / "config_used.toml", used)]
    t0, t1 = trajectory.span_s
    gps = dataset.gps
    reference_t = np.zeros(0)
    if gps is not None:  # without GPS no gps.tum: the run has no ATE reference
        gps_tr = gps_ahrs_trajectory(dataset)
        gps_in = (gps.t >= t0) & (gps.t <= t1)
        # the raw fixes (the ATE reference), with the AHRS heading for a full pose
        gps_pose = np.column_stack([gps.en_m[gps_in], gps_tr.poses(gps.t[gps_in])[:, 2]])
        gps_in_tr = Trajectory(gps.t[gps_in], gps_pose)
        files.append(write_atomic(out / GPS_FILE, lambda p: write_tum(p, gps_in_tr)))
        reference_t = gps.t
    if dataset.truth is not None:
        truth = truth_trajectory(dataset).clip(t0, t1)
        files.append(write_atomic(out / TRUTH_FILE, lambda p: write_tum(p, truth)))
        reference_t = np.concatenate([reference_t, truth.t_s])
    for name, tr in [(None, trajectory), *trajectories.items()]:
        stem = trajectory_stem(backend, name)
        dense = with_samples_at(tr, reference_t)
        files.append(write_atomic(out / f"{stem}.tum", partial(write_tum, trajectory=dense)))
        if dense.covs is not None:  # no file without covariances
            covs = partial(write_trajectory_covariances, trajectory=dense)
            files.append(write_atomic(out / cov_file(stem), covs))
    if closed_loop is not None:
        files += _write_closed_loop(out, dataset, backend, closed_loop, notes)
    files.append(write_json(out / "metrics.json", metrics))
    files.append(
        write_atomic(
            out / "report.png",
            lambda p: _report_figure(p, dataset, backend, trajectory, trajectories, metrics),
        )
    )
    if trajectory.covs is not None:
        streams = nis_streams(closed_loop) if closed_loop is not None else []
        files.append(
            write_atomic(
                out / CONSISTENCY_FILE,
                lambda p: write_consistency_figure(p, dataset, backend, trajectory, streams),
            )
        )
    return files


def _reference(dataset: Dataset) -> tuple[str, Trajectory] | None:
    """The reference of a run's pictures: the simulator's truth, else GPS + AHRS, else none."""
    if dataset.truth is not None:
        return "truth", truth_trajectory(dataset)
    if dataset.gps is not None:
        return "gps", gps_ahrs_trajectory(dataset)
    return None


def _walls(dataset: Dataset) -> np.ndarray | None:
    return truth_walls(dataset) if dataset.truth and "walls_m" in dataset.truth else None


def _report_figure(
    path: Path,
    dataset: Dataset,
    backend: str,
    trajectory: Trajectory,
    trajectories: dict[str, Trajectory],
    metrics: dict[str, Any],
) -> None:
    """report.png: the run's estimates (a factor graph's online, smoothed and batch ones) beside
    dead reckoning against its reference (:func:`plot_estimates`); a run with neither GPS nor
    truth draws its trajectories alone (:func:`_report_figure_without_reference`)."""
    if _reference(dataset) is None:
        _report_figure_without_reference(path, dataset, backend, trajectory, metrics)
        return
    drawn = {backend: trajectory}
    drawn |= {trajectory_stem(backend, name): tr for name, tr in trajectories.items()}
    if backend != "dr":  # dead reckoning beside every other back end, as the baseline
        drawn["dr"] = dead_reckoning_trajectory(dataset)
    plot_estimates(path, dataset, drawn, backend, span_s=trajectory.span_s)


def plot_estimates(
    path: Path,
    dataset: Dataset,
    estimates: dict[str, Trajectory],
    what: str,
    span_s: tuple[float, float] | None = None,
) -> Path:
    """Estimates against the dataset's reference (the simulator's truth, else GPS), in the
    plane and in time (:func:`sonarslam.slam.io.plots.plot_trajectories`), each with its ATE
    without alignment over the sonar span and the whole run (the figures of ``metrics.json``).

    Parameters
    ----------
    path : Path
        The PNG.
    estimates : dict of str to Trajectory
        By their style names (``dr``, ``ekf``, ``isam2``, ``isam2_smoothed``, ...:
        :func:`sonarslam.slam.io.maps.trajectory_style`).
    what : str
        What the title calls them.
    span_s : (float, float), optional
        The reference is drawn over it (Unix s; default the estimates' whole span).
    """
    found = _reference(dataset)
    assert found is not None, "plot_estimates needs GPS or the truth"
    ref_name, ref = found
    gps = dataset.gps
    t0 = min(tr.span_s[0] for tr in estimates.values()) if span_s is None else span_s[0]
    t1 = max(tr.span_s[1] for tr in estimates.values()) if span_s is None else span_s[1]
    errors = {
        name: truth_errors(tr, ref) if gps is None or ref_name == "truth" else ate_errors(tr, gps)
        for name, tr in estimates.items()
    }
    reference = "the truth" if ref_name == "truth" else "GPS"
    span = dataset.sonar_span_s
    spans = "over the whole run"
    if span is not None and (span[0] > t0 or span[1] < t1):
        a, b = max(span[0] - t0, 0.0), min(span[1], t1) - t0
        spans = (
            f"over the sonar span ({a:.0f} to {b:.0f} s: first to last beam; the rest shaded)"
            " and the whole run"
        )
    return plot_trajectories(
        path,
        {ref_name: ref.clip(t0, t1), **estimates},
        errors,
        f"{dataset.name}: {what} against {reference}, ATE without alignment {spans}",
        reference,
        span,
        _walls(dataset),
    )


def _report_figure_without_reference(
    path: Path, dataset: Dataset, backend: str, trajectory: Trajectory, metrics: dict[str, Any]
) -> None:
    """report.png of a run with neither GPS nor truth: the trajectories in the plane (the run
    beside dead reckoning), no position error (there is nothing to measure it against)."""
    drawn = {backend: trajectory}
    if backend != "dr":
        drawn["dr"] = dead_reckoning_trajectory(dataset)
    entropy = metrics.get("map_entropy_nats")
    sharp = f"map entropy {entropy:.3f} nats" if entropy is not None else "no map"
    plot_trajectories(
        path,
        drawn,
        {},
        f"{dataset.name}: {backend}, no GPS (no position error): {sharp}",
        "no reference",
        dataset.sonar_span_s,
        _walls(dataset),
    )


def _write_closed_loop(
    out: Path, dataset: Dataset, backend: str, result: ClosedLoopResult, notes: list[str] | None
) -> list[Path]:
    """map.json, lines.jsonl, the back end's files and map.png of a closed loop; the files.
    What ``graph.g2o`` leaves out goes to ``notes``: expected of the format, not a warning."""
    landmarks = result.backend.map_records()
    files = [write_json(out / "map.json", {"landmarks": landmarks}, indent=1)]
    lines = [
        json.dumps(json_safe({**f.to_json(), "landmark": lm}), allow_nan=False) + "\n"
        for f, lm in zip(result.features, result.feature_landmarks, strict=True)
    ]
    files.append(write_text(out / "lines.jsonl", "".join(lines)))
    for saved in write_files_into(out, result.backend.save):
        files.append(saved)
        if saved.name == "graph.json":
            export = graph_json_to_g2o(saved, warn=False)
            files.append(export.path)
            if notes is not None:
                notes.append(export.message())
    t0, t1 = result.trajectory.span_s
    beams = [b for b in dataset.nav_beams() if t0 <= b.t <= t1]
    points, _ = project_beams(
        beams,
        dataset.config.sonar,
        dataset.config.sonar_mounting,
        result.trajectory,
        map_min_intensity(beams),
    )
    reference = _reference(dataset)
    drawn = {backend: result.trajectory}
    if reference is not None:
        drawn = {reference[0]: reference[1].clip(t0, t1), **drawn}
    segments, bands = landmark_layers(landmarks, points)
    layers = MapLayers(
        points,
        drawn,
        segments,
        bands,
        _walls(dataset),
        segment_ids=[lm["id"] for lm in landmarks],
    )
    title = (
        f"{dataset.name}: {backend}, {len(landmarks)} landmarks (id, 95 % band) on"
        " the sonar bins projected with its trajectory"
    )
    files.append(write_atomic(out / "map.png", lambda p: plot_map(p, layers, title)))
    return files
