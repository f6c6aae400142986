"""sonarslam: line features with honest uncertainty from a mechanically scanned imaging sonar,
and SLAM with them.

The names a user needs are here (:data:`__all__`; the guide is ``docs/api.md``):

* the front end: :class:`LineExtractor` with its :class:`ExtractorConfig` (a run's preset:
  :func:`extractor_preset`), the beams (:class:`SonarBeam`) and poses it takes
  (:class:`PoseSource`) and the lines it gives (:class:`LineFeature`);
* your own SLAM: :class:`LandmarkAssociation` decides which line is which landmark from your
  estimate (:class:`WorldBelief`, or :func:`gtsam_belief` of your iSAM2 /
  ``Values``; :func:`local_to_world_covariance`) and returns a :class:`Decision`;
  :func:`line_factor` is the GTSAM factor of one observation, :func:`line_prediction` a
  filter's measurement model and :func:`world_observation` its new landmark's line;
  :class:`LandmarkConfig` the rules;
* data and runs: :func:`open_dataset` (a :class:`Dataset` from a directory or a ROS bag;
  :func:`dataset_from_arrays` from numpy arrays), :func:`dead_reckoning_trajectory`,
  :func:`run_backend` with a typed :class:`RunConfig`, :func:`offline_from_saved` (the
  factor graph's offline estimate of a saved run, with :class:`OfflineConfig`), and the simulator
  (:func:`make_scenario`, :func:`simulate_records` in memory, :func:`simulate` to files).

Each name is imported when first used (PEP 562), so ``import sonarslam`` loads none of gtsam,
numba or matplotlib. The layers are subpackages, in the order data flows through them:
:mod:`sonarslam.datasets` (readers and the simulator), :mod:`sonarslam.sonar` (the sensor),
:mod:`sonarslam.features` (the line front end), :mod:`sonarslam.slam` (back ends, evaluation,
the command line).
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:  # the names as a type checker sees them; at run time they load on first use
    from sonarslam.datasets.arrays import dataset_from_arrays
    from sonarslam.datasets.dataset import Dataset
    from sonarslam.datasets.simulator import make_scenario, simulate, simulate_records
    from sonarslam.datasets.source import open_dataset
    from sonarslam.features.config import ExtractorConfig
    from sonarslam.features.extractor import LineExtractor
    from sonarslam.features.line import LineFeature
    from sonarslam.features.pose_source import PoseSource
    from sonarslam.slam.backends.isam2.config import OfflineConfig
    from sonarslam.slam.backends.isam2.factors import line_factor
    from sonarslam.slam.mapping.landmarks import LandmarkConfig
    from sonarslam.slam.mapping.plugin import LandmarkAssociation, WorldBelief, gtsam_belief
    from sonarslam.slam.mapping.vote import Decision
    from sonarslam.slam.model.lines import (
        line_prediction,
        local_to_world_covariance,
        world_observation,
    )
    from sonarslam.slam.run.offline import offline_from_saved
    from sonarslam.slam.run.presets import RunConfig, extractor_preset
    from sonarslam.slam.run.run import run_backend
    from sonarslam.slam.run.sources import dead_reckoning_trajectory
    from sonarslam.sonar.beam import SonarBeam

#: Public name -> the module that defines it.
_HOMES: dict[str, str] = {
    # the front end
    "LineExtractor": "sonarslam.features.extractor",
    "ExtractorConfig": "sonarslam.features.config",
    "extractor_preset": "sonarslam.slam.run.presets",
    "PoseSource": "sonarslam.features.pose_source",
    "LineFeature": "sonarslam.features.line",
    "SonarBeam": "sonarslam.sonar.beam",
    # your own SLAM
    "LandmarkAssociation": "sonarslam.slam.mapping.plugin",
    "WorldBelief": "sonarslam.slam.mapping.plugin",
    "gtsam_belief": "sonarslam.slam.mapping.plugin",
    "local_to_world_covariance": "sonarslam.slam.model.lines",
    "line_prediction": "sonarslam.slam.model.lines",
    "world_observation": "sonarslam.slam.model.lines",
    "Decision": "sonarslam.slam.mapping.vote",
    "LandmarkConfig": "sonarslam.slam.mapping.landmarks",
    "line_factor": "sonarslam.slam.backends.isam2.factors",
    # data and runs
    "open_dataset": "sonarslam.datasets.source",
    "Dataset": "sonarslam.datasets.dataset",
    "dataset_from_arrays": "sonarslam.datasets.arrays",
    "dead_reckoning_trajectory": "sonarslam.slam.run.sources",
    "run_backend": "sonarslam.slam.run.run",
    "RunConfig": "sonarslam.slam.run.presets",
    "offline_from_saved": "sonarslam.slam.run.offline",
    "OfflineConfig": "sonarslam.slam.backends.isam2.config",
    "make_scenario": "sonarslam.datasets.simulator",
    "simulate_records": "sonarslam.datasets.simulator",
    "simulate": "sonarslam.datasets.simulator",
}

__all__ = [
    "Dataset",
    "Decision",
    "ExtractorConfig",
    "LandmarkAssociation",
    "LandmarkConfig",
    "LineExtractor",
    "LineFeature",
    "OfflineConfig",
    "PoseSource",
    "RunConfig",
    "SonarBeam",
    "WorldBelief",
    "dataset_from_arrays",
    "dead_reckoning_trajectory",
    "extractor_preset",
    "gtsam_belief",
    "line_factor",
    "line_prediction",
    "local_to_world_covariance",
    "make_scenario",
    "offline_from_saved",
    "open_dataset",
    "run_backend",
    "simulate",
    "simulate_records",
    "world_observation",
]


def __getattr__(name: str) -> Any:
    """A public name, imported from its module on first use and kept here (PEP 562);
    ``__version__`` is the installed distribution's version."""
    if name == "__version__":
        from importlib.metadata import version

        return version("sonarslam")
    home = _HOMES.get(name)
    if home is None:
        raise AttributeError(f"module 'sonarslam' has no attribute {name!r}")
    value = getattr(importlib.import_module(home), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    """The public names (:data:`__all__`) and ``__version__``, not the module's own imports."""
    return sorted({*__all__, "__version__"})
