"""The MSIS simulator: the runs whose right answer is known.

``simulate(kind, seed, out_dir)`` writes a run in the marina layout with its ``truth.json``
(kinds: :data:`KINDS`); ``simulate_records(make_scenario(kind, seed))`` gives the same run in
memory.

Modules: ``world`` (walls and the fixed worlds), ``layout`` (harbours drawn per seed), ``path`` (true motion), ``msis`` (the sonar beam model),
``sensors`` (DVL, AHRS, GPS), ``scenario`` (what is simulated, in memory), ``writer`` (files).
"""

from sonarslam.datasets.simulator.layout import drawn_world
from sonarslam.datasets.simulator.msis import EchoModel, beam_axis_hits, cast_rays, simulate_msis
from sonarslam.datasets.simulator.path import (
    TrueMotion,
    free_path,
    stationary,
    survey,
    waypoint_path,
)
from sonarslam.datasets.simulator.scenario import (
    HELD_BACK_SEED_MIN,
    KINDS,
    Scenario,
    Simulation,
    draw_drift_errors,
    make_scenario,
    make_world,
    simulate_records,
)
from sonarslam.datasets.simulator.sensors import DriftErrors, GeodeticOrigin, SensorNoise
from sonarslam.datasets.simulator.world import (
    World,
    drift_world,
    harbour_world,
    pool_world,
    random_harbour_world,
)
from sonarslam.datasets.simulator.writer import simulate, write_dataset

__all__ = [
    "HELD_BACK_SEED_MIN",
    "KINDS",
    "DriftErrors",
    "EchoModel",
    "GeodeticOrigin",
    "Scenario",
    "SensorNoise",
    "Simulation",
    "TrueMotion",
    "World",
    "beam_axis_hits",
    "cast_rays",
    "draw_drift_errors",
    "drawn_world",
    "drift_world",
    "free_path",
    "harbour_world",
    "make_scenario",
    "make_world",
    "pool_world",
    "random_harbour_world",
    "simulate",
    "simulate_msis",
    "simulate_records",
    "stationary",
    "survey",
    "waypoint_path",
    "write_dataset",
]
