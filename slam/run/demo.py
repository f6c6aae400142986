"""The main job of ``make run`` (``sonarslam demo``): both closed loops beside dead reckoning on
the real marina when ``$SONARSLAM_DATA`` holds it, otherwise on a freshly simulated harbour
(and it says so: :func:`demo_source`); and the sonar map with GPS poses."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from sonarslam.datasets.simulator import simulate
from sonarslam.datasets.source import ENV_VAR, MARINA_DOCS, data_root, open_dataset
from sonarslam.features.projection import project_beams
from sonarslam.slam.eval.truth import truth_walls
from sonarslam.slam.io.files import write_atomic
from sonarslam.slam.io.maps import plot_scans
from sonarslam.slam.io.trajectory import trajectory_stem
from sonarslam.slam.run.outputs import plot_estimates
from sonarslam.slam.run.presets import map_min_intensity
from sonarslam.slam.run.run import RunResult, run
from sonarslam.slam.run.sources import gps_ahrs_trajectory

__all__ = ["DEMO_BACKENDS", "DemoSource", "demo_source", "main_job"]

#: What the main job runs, in this order (dead reckoning first: the baseline).
DEMO_BACKENDS = ("dr", "ekf", "isam2")
#: The simulated harbour of the main job without the marina.
SIM_SEED, SIM_DURATION_S = 0, 600.0


@dataclass(frozen=True)
class DemoSource:
    """What the main job runs on.

    Attributes
    ----------
    name : str
        ``"marina"`` or ``"sim_harbour_0"``: the prefix of the run directories.
    simulated : bool
        A simulated harbour: its figures are against the simulator's truth.
    description : str
        One line for the terminal: what runs on what, and why.
    """

    name: str
    simulated: bool
    description: str


def demo_source(duration_s: float = SIM_DURATION_S) -> DemoSource:
    """The marina under ``$SONARSLAM_DATA`` if it is there, else a simulated harbour."""
    root = data_root()
    runs = ", ".join(DEMO_BACKENDS)
    if root is not None and (root / "marina").is_dir():
        return DemoSource(
            "marina", False, f"{runs} on the real marina ({root / 'marina'}), against GPS"
        )
    where = f"${ENV_VAR} is not set" if root is None else f"no marina/ under ${ENV_VAR}={root}"
    return DemoSource(
        f"sim_harbour_{SIM_SEED}",
        True,
        f"{runs} on a simulated harbour (seed {SIM_SEED}, {duration_s:g} s), because {where}; "
        "its figures are against the simulator's truth (how to get the marina: "
        f"{MARINA_DOCS})",
    )


def main_job(
    out_dir: str | Path,
    progress: bool = True,
    source: DemoSource | None = None,
    duration_s: float = SIM_DURATION_S,
) -> list[RunResult]:
    """Run :data:`DEMO_BACKENDS` (``isam2`` with its batch pass) into ``out_dir/<name>-<backend>``
    and draw ``out_dir/<name>_scans_gps.png`` (the sonar map with GPS poses) and
    ``out_dir/<name>_trajectories.png`` (every estimate against the reference); returns the run
    results (dead reckoning first).

    ``source``: :func:`demo_source`'s choice (default: made here); ``duration_s``: the length of
    the simulated harbour when there is no marina (s).
    """
    out = Path(out_dir)
    chosen = source or demo_source(duration_s)
    data: str | Path = "marina"
    if chosen.simulated:
        data = simulate("harbour", seed=SIM_SEED, out_dir=out / chosen.name, duration_s=duration_s)
    # the factor graph's smoothed trajectory and a final batch pass are outputs beside its
    # online one
    results = [
        run(
            data,
            backend,
            out / f"{chosen.name}-{backend}",
            progress=progress,
            batch=backend == "isam2",
        )
        for backend in DEMO_BACKENDS
    ]
    dataset = open_dataset(data)
    gps = gps_ahrs_trajectory(dataset)
    beams = dataset.nav_beams()
    points, _ = project_beams(
        beams, dataset.config.sonar, dataset.config.sonar_mounting, gps, map_min_intensity(beams)
    )
    title = f"{chosen.name}: sonar bins projected with GPS poses"
    if chosen.simulated:
        title += " (simulated GPS), the true walls dashed"
    walls = truth_walls(dataset) if dataset.truth and "walls_m" in dataset.truth else None
    write_atomic(
        out / f"{chosen.name}_scans_gps.png",
        lambda p: plot_scans(p, points, {"gps": gps}, title, walls),
    )
    # every estimate in one picture, each with the figures of its row of the results table
    estimates = {
        trajectory_stem(r.backend, name): tr
        for r in results
        for name, tr in [(None, r.trajectory), *r.trajectories.items()]
    }
    write_atomic(
        out / f"{chosen.name}_trajectories.png",
        lambda p: plot_estimates(p, dataset, estimates, "every estimate"),
    )
    return results
