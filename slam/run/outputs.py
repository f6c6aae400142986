"""The files of a run directory (``sonarslam run --out DIR``).

* ``trajectory.tum`` (and its covariances ``trajectory_cov.npz``), ``ground_truth.tum`` (the GPS
  fixes inside the run with the AHRS heading), ``metrics.json``, ``config_used.toml`` (the
  dataset configuration used), ``report.png`` (trajectories against GPS beside dead reckoning);
* closed loops also ``map.json`` (the landmarks), ``lines.jsonl`` (every line with the landmark
  it was associated with), ``map.png`` (the landmarks over the sonar bins projected with the
  run's trajectory), one ``trajectory_<name>.tum`` per other trajectory of the back end
  (``smoothed``, ``batch``) and whatever the back end saves (``graph.json``).
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np

from datasets.config import dump_dataset_config
from datasets.source import Dataset
from features.projection import project_beams
from slam.eval.ate import ate_errors
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
    out.mkdir(parents=True, exist_ok=True)
    (out / "config_used.toml").write_text(dump_dataset_config(dataset.config))
    write_tum(out / "trajectory.tum", trajectory)
    write_trajectory_covariances(out / COV_FILE, trajectory)  # no-op without covariances
    t0, t1 = trajectory.span_s
    gps = dataset.gps
    gps_tr = gps_ahrs_trajectory(dataset)
    gps_in = (gps.t >= t0) & (gps.t <= t1)
    # the raw fixes (the ATE reference), with the AHRS heading for a full pose
    gps_pose = np.column_stack([gps.en_m[gps_in], gps_tr.poses(gps.t[gps_in])[:, 2]])
    write_tum(out / "ground_truth.tum", Trajectory(gps.t[gps_in], gps_pose))
    for name, tr in trajectories.items():
        write_tum(out / f"trajectory_{name}.tum", tr)
    if closed_loop is not None:
        _write_closed_loop(out, dataset, closed_loop, gps_tr)
    (out / "metrics.json").write_text(json.dumps(metrics, indent=2) + "\n")
    drawn = {"gps": gps_tr, backend: trajectory}
    if backend != "dr":  # dead reckoning beside every other back end, as the reference
        drawn["dr"] = dead_reckoning_trajectory(dataset)
    errors = {name: ate_errors(tr, gps) for name, tr in drawn.items() if name != "gps"}
    plot_trajectories(
        out / "report.png",
        drawn,
        errors,
        f"{dataset.name}: {backend}, ATE mean {metrics['ate_mean_m']:.2f} m, "
        f"max {metrics['ate_max_m']:.2f} m",
    )
    return out


def _write_closed_loop(
    out: Path, dataset: Dataset, result: ClosedLoopResult, gps_tr: Trajectory
) -> None:
    """map.json, lines.jsonl, the back end's files and map.png of a closed loop."""
    landmarks = result.backend.map_records()
    (out / "map.json").write_text(json.dumps({"landmarks": landmarks}, indent=1) + "\n")
    with (out / "lines.jsonl").open("w") as fh:
        for f, lm in zip(result.features, result.feature_landmarks, strict=True):
            fh.write(json.dumps({**f.to_json(), "landmark": lm}) + "\n")
    result.backend.save(out)
    t0, t1 = result.trajectory.span_s
    beams = [b for b in dataset.nav_beams() if t0 <= b.t <= t1]
    points, _ = project_beams(
        beams,
        dataset.config.sonar,
        dataset.config.sonar_mounting,
        result.trajectory,
        map_min_intensity(beams),
    )
    plot_scans(
        out / "map.png",
        points,
        {"gps": gps_tr, "est": result.trajectory},
        f"{dataset.name}: map and trajectory, sonar bins projected with the estimate",
        [np.asarray(lm["endpoints"]) for lm in landmarks],
    )
