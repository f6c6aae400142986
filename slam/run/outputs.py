"""The files of a run directory (``sonarslam run --out DIR``; the README's table of outputs).

* ``<backend>.tum`` (``dr.tum``, ``ekf.tum``, ``isam2.tum``; ``gps_ahrs.tum`` for the ``gps``
  baseline) and its covariances ``<backend>_cov.npz``; ``gps.tum`` (the GPS fixes inside the
  run with the AHRS heading: the ATE's reference); on simulated data ``truth.tum`` (the true
  poses inside the run); ``metrics.json``, ``config_used.toml`` (the dataset configuration
  used), ``report.png`` (trajectories against the reference beside dead reckoning),
  ``consistency.png`` when the trajectory has covariances (NEES against the truth or GPS, and a
  closed loop's NIS, in time with their chi2 bands: :mod:`sonarslam.slam.run.consistency_figure`).
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
from sonarslam.slam.run.sources import DR_IGNORES, dead_reckoning_trajectory, gps_ahrs_trajectory

__all__ = ["write_run"]


def write_run(
    out: Path,
    dataset: Dataset,
    backend: str,
    trajectory: Trajectory,
    metrics: dict[str, Any],
    closed_loop: ClosedLoopResult | None,
    trajectories: dict[str, Trajectory],
) -> list[Path]:
    """Write a run's files into ``out`` (created); returns the files written, in order (what
    was in ``out`` before, another run's files, is not among them)."""
    assert dataset.gps is not None, "a run has GPS (checked by run_backend)"
    make_output_dir(out)
    used = dump_dataset_config(dataset.config)
    if backend == "dr":
        used = "".join(f"# ignored by dead reckoning: {key}\n" for key in DR_IGNORES) + used
    files = [write_text(out / "config_used.toml", used)]
    t0, t1 = trajectory.span_s
    gps = dataset.gps
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
        reference_t = np.concatenate([gps.t, truth.t_s])
    for name, tr in [(None, trajectory), *trajectories.items()]:
        stem = trajectory_stem(backend, name)
        dense = with_samples_at(tr, reference_t)
        files.append(write_atomic(out / f"{stem}.tum", partial(write_tum, trajectory=dense)))
        if dense.covs is not None:  # no file without covariances
            covs = partial(write_trajectory_covariances, trajectory=dense)
            files.append(write_atomic(out / cov_file(stem), covs))
    if closed_loop is not None:
        files += _write_closed_loop(out, dataset, backend, closed_loop)
    files.append(write_json(out / "metrics.json", metrics))
    files.append(
        write_atomic(
            out / "report.png",
            lambda p: _report_figure(p, dataset, backend, trajectory, metrics),
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


def _reference(dataset: Dataset) -> tuple[str, Trajectory]:
    """The reference of a run's pictures: the simulator's truth, else GPS + AHRS."""
    if dataset.truth is not None:
        return "truth", truth_trajectory(dataset)
    return "gps", gps_ahrs_trajectory(dataset)


def _walls(dataset: Dataset) -> np.ndarray | None:
    return truth_walls(dataset) if dataset.truth and "walls_m" in dataset.truth else None


def _report_figure(
    path: Path, dataset: Dataset, backend: str, trajectory: Trajectory, metrics: dict[str, Any]
) -> None:
    """report.png: the run beside dead reckoning against its reference, in the plane and in time."""
    assert dataset.gps is not None
    ref_name, ref = _reference(dataset)
    t0, t1 = trajectory.span_s
    drawn = {ref_name: ref.clip(t0, t1), backend: trajectory}
    if backend != "dr":  # dead reckoning beside every other back end, as the baseline
        drawn["dr"] = dead_reckoning_trajectory(dataset)
    errors = {
        name: truth_errors(tr, ref) if ref_name == "truth" else ate_errors(tr, dataset.gps)
        for name, tr in drawn.items()
        if name != ref_name
    }
    m, key = metrics, "ate_truth" if ref_name == "truth" else "ate"
    spans = f"whole run mean {m[key + '_mean_m']:.2f} m, max {m[key + '_max_m']:.2f} m"
    if "ate_sonar_mean_m" in m and ref_name == "gps":
        spans = (
            f"sonar span mean {m['ate_sonar_mean_m']:.2f} m, max {m['ate_sonar_max_m']:.2f} m; "
            + spans
        )
    reference = "the truth" if ref_name == "truth" else "GPS"
    plot_trajectories(
        path,
        drawn,
        errors,
        f"{dataset.name}: {backend} against {reference}: {spans}",
        reference,
        dataset.sonar_span_s,
        _walls(dataset),
    )


def _write_closed_loop(
    out: Path, dataset: Dataset, backend: str, result: ClosedLoopResult
) -> list[Path]:
    """map.json, lines.jsonl, the back end's files and map.png of a closed loop; the files."""
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
            files.append(graph_json_to_g2o(saved).path)
    t0, t1 = result.trajectory.span_s
    beams = [b for b in dataset.nav_beams() if t0 <= b.t <= t1]
    points, _ = project_beams(
        beams,
        dataset.config.sonar,
        dataset.config.sonar_mounting,
        result.trajectory,
        map_min_intensity(beams),
    )
    ref_name, ref = _reference(dataset)
    segments, bands = landmark_layers(landmarks, points)
    layers = MapLayers(
        points,
        {ref_name: ref.clip(t0, t1), backend: result.trajectory},
        segments,
        bands,
        _walls(dataset),
    )
    title = (
        f"{dataset.name}: {backend}, {len(landmarks)} landmarks with 95 % bands over the sonar"
        " bins projected with its trajectory"
    )
    files.append(write_atomic(out / "map.png", lambda p: plot_map(p, layers, title)))
    return files
