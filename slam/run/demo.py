"""The main job of ``make run`` (``sonarslam demo``): both closed loops beside dead reckoning on
the real marina when ``$SONARSLAM_DATA`` holds it, otherwise on a freshly simulated harbour; and
the sonar map with GPS poses."""

from __future__ import annotations

from pathlib import Path

from datasets.simulator import simulate
from datasets.source import data_root, open_dataset
from features.projection import project_beams
from slam.eval.truth import truth_walls
from slam.io.files import write_atomic
from slam.io.maps import plot_scans
from slam.run.presets import map_min_intensity
from slam.run.run import RunResult, run
from slam.run.sources import gps_ahrs_trajectory

__all__ = ["main_job"]


def main_job(out_dir: str | Path, progress: bool = True) -> list[RunResult]:
    """Run ``dr``, ``ekf`` and ``isam2`` (with its batch pass) into ``out_dir/<name>-<backend>`` and draw
    ``out_dir/<name>_scans_gps.png``; returns the run results (dead reckoning first)."""
    out = Path(out_dir)
    root = data_root()
    if root is not None and (root / "marina").is_dir():
        source: str | Path = "marina"
        name = "marina"
    else:
        source = simulate("harbour", seed=0, out_dir=out / "sim_harbour_0")
        name = "sim_harbour_0"
    # the factor graph's smoothed trajectory and a final batch pass are outputs beside its
    # online one
    results = [
        run(source, backend, out / f"{name}-{backend}", progress=progress, batch=backend == "isam2")
        for backend in ("dr", "ekf", "isam2")
    ]
    dataset = open_dataset(source)
    gps = gps_ahrs_trajectory(dataset)
    beams = dataset.nav_beams()
    points, _ = project_beams(
        beams, dataset.config.sonar, dataset.config.sonar_mounting, gps, map_min_intensity(beams)
    )
    title = f"{name}: sonar bins projected with GPS poses"
    walls = truth_walls(dataset) if dataset.truth and "walls_m" in dataset.truth else None
    write_atomic(
        out / f"{name}_scans_gps.png",
        lambda p: plot_scans(p, points, {"gps": gps}, title, walls),
    )
    return results
