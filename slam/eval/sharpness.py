"""The sharpness of the sonar map a trajectory projects: a GPS-free score of its consistency.

Every bin of every beam is placed in the world with the trajectory's pose at its beam's time
(:func:`sonarslam.features.projection.project_beams`); the Shannon entropy of the 2-D histogram of those
points in square cells (:func:`map_entropy`) is low when the walls seen from different places
and passes fall on the same cells, and grows as the trajectory smears them. Over a window of a
minute it scores the local motion (the sonar clock, the scan direction and the sonar yaw are
calibrated so, :mod:`sonarslam.slam.run.calibration`); over the whole run it scores the revisits too,
without a ruler: a loop that moves the trajectory onto its earlier passes sharpens the map.
Values compare trajectories of one dataset with one cell size only (nats).
"""

from __future__ import annotations

import numpy as np

from sonarslam.datasets.source import Dataset
from sonarslam.features.geometry import FloatArray
from sonarslam.features.pose_source import PoseSource
from sonarslam.features.projection import project_beams

__all__ = ["map_entropy", "map_entropy_variance", "trajectory_sharpness"]


def _cell_counts(points_w: FloatArray, cell_m: float) -> np.ndarray:
    """Points per occupied cell of the 2D histogram of ``points_w`` ``(N, 2)``, N > 0."""
    ij = np.floor(points_w / cell_m).astype(np.int64)
    ij -= ij.min(axis=0)
    keys = ij[:, 0] * (int(ij[:, 1].max()) + 1) + ij[:, 1]
    return np.bincount(np.unique(keys, return_inverse=True)[1])


def map_entropy(points_w: FloatArray, cell_m: float) -> float:
    """Shannon entropy (nats) of the 2D histogram of points ``(N, 2)`` with square cells."""
    if points_w.shape[0] == 0:
        return 0.0
    counts = _cell_counts(points_w, cell_m)
    p = counts / counts.sum()
    return float(-(p * np.log(p)).sum())


def map_entropy_variance(points_w: FloatArray, cell_m: float) -> float:
    """Sampling variance (nats^2) of :func:`map_entropy` of ``N`` points ``(N, 2)``: the
    first-order (delta-method) variance of the plug-in entropy of ``N`` draws from the cells'
    frequencies ``p``, ``(sum p ln^2 p - H^2) / N`` (Basharin 1959); 0 without points. The
    spread the entropy would have over re-drawn echoes of the same map: the unit in which a
    difference of entropies is judged (:mod:`sonarslam.slam.run.calibration`)."""
    if points_w.shape[0] == 0:
        return 0.0
    counts = _cell_counts(points_w, cell_m)
    p = counts / counts.sum()
    log_p = np.log(p)
    h = -(p * log_p).sum()
    return float(max((p * log_p**2).sum() - h**2, 0.0) / points_w.shape[0])


def trajectory_sharpness(
    dataset: Dataset,
    trajectory: PoseSource,
    span_s: tuple[float, float],
    min_intensity: int = 1,
    cell_m: float = 0.5,
) -> float:
    """:func:`map_entropy` of the bins at or above ``min_intensity`` of the dataset's beams
    inside ``span_s`` projected with ``trajectory`` (nats; lower is sharper). Raw beams need
    the threshold of their echoes (:func:`sonarslam.slam.run.presets.map_min_intensity`): their
    background noise would fill every cell."""
    beams = [b for b in dataset.nav_beams() if span_s[0] <= b.t <= span_s[1]]
    points, _ = project_beams(
        beams, dataset.config.sonar, dataset.config.sonar_mounting, trajectory, min_intensity
    )
    return map_entropy(points, cell_m)
