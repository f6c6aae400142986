"""The leading edges of echo bands, projected into the world by a ruler (for wall references).

A wall's echo is a band of returns several metres thick along a beam; its near edge is where the
wall's face is. Each beam's returns (the non-zero bins of a 0/255 mask; raw beams: the bins at
or above ``intensity_threshold``) are cut into runs, a run being a chain of returns whose gaps
are shorter than ``run_gap_m``, and the nearest bin of each run is kept: the rule of
:func:`sonarslam.sonar.segmentation.leading_edge_bins`, which the scan matcher uses too. Second returns and far echoes give leading
edges too; they lie behind the walls, and the wall fit (:mod:`sonarslam.slam.eval.walls`) treats them as
outliers.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import asdict, dataclass, replace
from typing import Any

import numpy as np

from sonarslam.features.geometry import FloatArray, compose
from sonarslam.features.pose_source import PoseSource
from sonarslam.features.projection import project_beams
from sonarslam.sonar.beam import Mounting, SonarBeam, SonarHead
from sonarslam.sonar.segmentation import leading_edge_bins

__all__ = ["EdgeConfig", "Edges", "leading_edge_beams", "leading_edge_points"]


@dataclass(frozen=True)
class EdgeConfig:
    """Which bins are returns and how they make runs.

    Attributes
    ----------
    run_gap_m : float
        Returns closer than this along a beam are one run (m); the marina preset's
        ``min_distance_m``.
    min_range_m : float
        Bins nearer than this are ignored (m).
    max_range_m : float or None
        Bins farther than this are ignored (m); None: all.
    intensity_threshold : float
        Raw beams: a bin at or above this is a return (masks: every non-zero bin).
    """

    run_gap_m: float = 1.0
    min_range_m: float = 1.0
    max_range_m: float | None = None
    intensity_threshold: float = 60.0

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)


@dataclass(frozen=True, eq=False)
class Edges:
    """Leading edges in the world.

    Attributes
    ----------
    points_w : ndarray, shape (N, 2)
        The edges (world, m).
    sonar_w : ndarray, shape (N, 2)
        Where the sonar was when each was seen (m): the water side of its wall.
    t_s : ndarray, shape (N,)
        Beam times (Unix s).
    """

    points_w: FloatArray
    sonar_w: FloatArray
    t_s: FloatArray

    def sightings(self, idx: np.ndarray, window_s: float) -> float:
        """In how many windows of ``window_s`` the edges ``idx`` were seen, as the effective
        number ``1 / sum(p_k ** 2)`` of the shares ``p_k`` of the edges in each window (inverse
        Simpson index): a wall seen evenly over ``K`` windows gives ``K``, a wake streak of one
        pass with a few stray clutter points in other windows about 1."""
        _, counts = np.unique(np.floor(self.t_s[idx] / window_s), return_counts=True)
        if counts.size == 0:
            return 0.0
        p = counts / counts.sum()
        return float(1.0 / np.sum(p**2))


def leading_edge_beams(
    beams: Sequence[SonarBeam], head: SonarHead, config: EdgeConfig | None = None
) -> list[SonarBeam]:
    """The beams as 0/255 masks holding only the nearest bin of each run of returns.

    Parameters
    ----------
    beams : list of SonarBeam
        Masks (``thresholded``) or raw intensities.
    head : SonarHead
    config : EdgeConfig, optional

    Returns
    -------
    list of SonarBeam
        Same times and angles, ``thresholded=True``.
    """
    cfg = config or EdgeConfig()
    out = []
    for b in beams:
        bins = leading_edge_bins(
            b,
            head,
            run_gap_m=cfg.run_gap_m,
            min_range_m=cfg.min_range_m,
            max_range_m=cfg.max_range_m,
            intensity_threshold=cfg.intensity_threshold,
        )
        edges = np.zeros(b.intensities.shape, dtype=np.uint8)
        edges[bins] = 255
        out.append(replace(b, intensities=edges, thresholded=True))
    return out


def leading_edge_points(
    beams: Sequence[SonarBeam],
    head: SonarHead,
    sonar_mounting: Mounting,
    pose_source: PoseSource,
    config: EdgeConfig | None = None,
) -> Edges:
    """The leading edges of ``beams`` projected with ``pose_source`` (the ruler), with the sonar
    position of each (:class:`Edges`)."""
    points_w, t_s = project_beams(
        leading_edge_beams(beams, head, config), head, sonar_mounting, pose_source, 255
    )
    sonar_w = compose(pose_source.poses(t_s), sonar_mounting.as_pose())[:, :2]
    return Edges(points_w, np.ascontiguousarray(sonar_w), t_s)
