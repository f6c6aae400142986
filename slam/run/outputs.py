"""The files of a run directory (``sonarslam run --out DIR``).

* ``trajectory.tum`` (and its covariances ``trajectory_cov.npz``), ``ground_truth.tum`` (the GPS
  fixes inside the run with the AHRS heading), ``metrics.json``, ``config_used.toml`` (the
  dataset configuration used), ``report.png`` (trajectories against GPS beside dead reckoning);
* closed loops also ``map.json`` (the landmarks), ``lines.jsonl`` (every line with the landmark
  it was associated with), ``map.png`` (the landmarks over the sonar bins projected with the
  run's trajectory), one ``trajectory_<name>.tum`` per other trajectory of the back end
  (``smoothed``, ``batch``) and whatever the back end saves (``graph.json``).

Every file is written under a temporary name and renamed when whole (:mod:`slam.io.files`);
``metrics.json`` is strict JSON (null where a figure is undefined).
"""

from __future__ import annotations

import json
from functools import partial
from pathlib import Path
from typing import Any

import numpy as np

from datasets.config import dump_dataset_config
from datasets.source import Dataset
from features.projection import project_beams
from slam.eval.ate import ate_errors
from slam.io.files import (
    json_safe,
    make_output_dir,
    write_atomic,
    write_files_into,
    write_json,
    write_text,
)
from slam.io.plots import plot_scans, plot_trajectories
from slam.io.trajectory import COV_FILE, Trajectory, write_trajectory_covariances, write_tum
from slam.run.closed_loop import ClosedLoopResult
from slam.run.presets import map_min_intensity
from slam.run.sources import dead_reckoning_trajectory, gps_ahrs_trajectory

__all__ = ["write_run"]


def write_run(
    out: Path,
    dataset: Dataset,
    backend: str,
    trajectory: Trajectory,
    metrics: dict[str, Any],
    closed_loop: ClosedLoopResult | None,
    trajectories: dict[str, Trajectory],
) -> Path:
    """Write a run's files into ``out`` (created); returns ``out``."""
    assert dataset.gps is not None, "a run has GPS (checked by run_backend)"
    make_output_dir(out)
    write_text(out / "config_used.toml", dump_dataset_config(dataset.config))
    write_atomic(out / "trajectory.tum", lambda p: write_tum(p, trajectory))
    # no file without covariances
    write_atomic(out / COV_FILE, lambda p: write_trajectory_covariances(p, trajectory))
    t0, t1 = trajectory.span_s
    gps = dataset.gps
    gps_tr = gps_ahrs_trajectory(dataset)
    gps_in = (gps.t >= t0) & (gps.t <= t1)
    # the raw fixes (the ATE reference), with the AHRS heading for a full pose
    gps_pose = np.column_stack([gps.en_m[gps_in], gps_tr.poses(gps.t[gps_in])[:, 2]])
    truth_tr = Trajectory(gps.t[gps_in], gps_pose)
    write_atomic(out / "ground_truth.tum", lambda p: write_tum(p, truth_tr))
    for name, tr in trajectories.items():
        write_atomic(out / f"trajectory_{name}.tum", partial(write_tum, trajectory=tr))
    if closed_loop is not None:
        _write_closed_loop(out, dataset, closed_loop, gps_tr)
    write_json(out / "metrics.json", metrics)
    drawn = {"gps": gps_tr, backend: trajectory}
    if backend != "dr":  # dead reckoning beside every other back end, as the reference
        drawn["dr"] = dead_reckoning_trajectory(dataset)
    errors = {name: ate_errors(tr, gps) for name, tr in drawn.items() if name != "gps"}
    title = (
        f"{dataset.name}: {backend}, ATE mean {metrics['ate_mean_m']:.2f} m, "
        f"max {metrics['ate_max_m']:.2f} m"
    )
    write_atomic(out / "report.png", lambda p: plot_trajectories(p, drawn, errors, title))
    return out


def _write_closed_loop(
    out: Path, dataset: Dataset, result: ClosedLoopResult, gps_tr: Trajectory
) -> None:
    """map.json, lines.jsonl, the back end's files and map.png of a closed loop."""
    landmarks = result.backend.map_records()
    write_json(out / "map.json", {"landmarks": landmarks}, indent=1)
    lines = [
        json.dumps(json_safe({**f.to_json(), "landmark": lm}), allow_nan=False) + "\n"
        for f, lm in zip(result.features, result.feature_landmarks, strict=True)
    ]
    write_text(out / "lines.jsonl", "".join(lines))
    write_files_into(out, result.backend.save)
    t0, t1 = result.trajectory.span_s
    beams = [b for b in dataset.nav_beams() if t0 <= b.t <= t1]
    points, _ = project_beams(
        beams,
        dataset.config.sonar,
        dataset.config.sonar_mounting,
        result.trajectory,
        map_min_intensity(beams),
    )
    write_atomic(
        out / "map.png",
        lambda p: plot_scans(
            p,
            points,
            {"gps": gps_tr, "est": result.trajectory},
            f"{dataset.name}: map and trajectory, sonar bins projected with the estimate",
            [np.asarray(lm["endpoints"]) for lm in landmarks],
        ),
    )
