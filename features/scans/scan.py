"""Scans: the leading edges of one turn of the head, motion-corrected into one body frame.

A scan gathers ``beams_per_scan`` consecutive beams (a full turn by default). Each beam keeps
the leading edge of each run of returns (:func:`sonarslam.sonar.segmentation.leading_edge_bins`: where a
wall's face is on a thick echo band) as range and bearing. When the scan is complete, every
point is placed with the pose of its own beam from the :class:`sonarslam.features.pose_source.PoseSource`
(the closed loop's) and brought into the body frame of the scan's last beam, its *reference*:
``p_ref = inverse(wTb(t_ref)) * wTb(t_beam) * bTs * (r cos b, r sin b)``. This is the motion
correction (the vehicle moves metres during a turn); between two scans only the poses' relative
motion over the scan matters, which the odometry gives well.

A *submap* (:func:`submap_points`) joins consecutive scans in the frame of one of them, with the
relative poses of their references from the pose source.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from sonarslam.features.geometry import FloatArray, between, compose, inverse, transform_points
from sonarslam.features.pose_source import PoseSource, checked_poses
from sonarslam.features.scans.config import ScanConfig
from sonarslam.sonar.beam import Mounting, SonarBeam, SonarHead
from sonarslam.sonar.segmentation import leading_edge_bins

__all__ = ["Scan", "ScanBuilder", "submap_points"]


@dataclass(frozen=True, eq=False)
class Scan:
    """One motion-corrected scan.

    Attributes
    ----------
    index : int
        0, 1, 2, ... in the order the scans were completed.
    t_ref_s : float
        Its reference time: the last beam's (Unix s).
    t_first_s : float
        The first beam's time (Unix s).
    points_b : ndarray, shape (N, 2)
        Leading edges in the body frame at ``t_ref_s`` (m).
    wTb_ref : ndarray, shape (3,)
        The body pose at ``t_ref_s`` the pose source gave when the scan was completed.
    n_beams : int
    """

    index: int
    t_ref_s: float
    t_first_s: float
    points_b: FloatArray
    wTb_ref: FloatArray
    n_beams: int


class ScanBuilder:
    """Beams in, complete motion-corrected scans out (module docstring).

    Parameters
    ----------
    config : ScanConfig
    head : SonarHead
    sonar_mounting : Mounting
        ``bTs`` of the sonar head.
    pose_source : PoseSource
        The body pose of every beam (the closed loop's own).
    """

    def __init__(
        self, config: ScanConfig, head: SonarHead, sonar_mounting: Mounting, pose_source: PoseSource
    ) -> None:
        self.config = config
        self.head = head
        self.bTs = sonar_mounting.as_pose()
        self.pose_source = pose_source
        self.n_beams = config.beams_per_scan or int(round(2.0 * np.pi / head.step_rad))
        self._t: list[float] = []
        self._bearing: list[float] = []
        self._ranges: list[FloatArray] = []
        self._count = 0

    def add(self, beam: SonarBeam) -> Scan | None:
        """Take one beam; the scan it completes, else None."""
        cfg = self.config
        bins = leading_edge_bins(
            beam,
            self.head,
            run_gap_m=cfg.run_gap_m,
            min_range_m=cfg.min_range_m,
            max_range_m=cfg.max_range_m,
            intensity_threshold=cfg.intensity_threshold,
        )
        self._t.append(beam.t)
        self._bearing.append(float(self.head.bearing_rad(beam.transducer_angle_rad)))
        self._ranges.append(self.head.bin_range_m(bins, beam.bin_size_m))
        if len(self._t) < self.n_beams:
            return None
        scan = self._complete()
        self._t, self._bearing, self._ranges = [], [], []
        return scan

    def _complete(self) -> Scan:
        t = np.asarray(self._t)
        poses = checked_poses(self.pose_source, t)  # (n_beams, 3); the last is the reference
        wTs = compose(poses, self.bTs)
        refTs = compose(inverse(poses[-1]), wTs)
        counts = np.array([r.size for r in self._ranges])
        r = np.concatenate(self._ranges) if counts.sum() else np.zeros(0)
        bearing = np.repeat(np.asarray(self._bearing), counts)
        local = np.column_stack([r * np.cos(bearing), r * np.sin(bearing)])
        points = transform_points(np.repeat(refTs, counts, axis=0), local).reshape(-1, 2)
        scan = Scan(self._count, float(t[-1]), float(t[0]), points, poses[-1].copy(), t.size)
        self._count += 1
        return scan


def submap_points(scans: list[Scan], centre: int, pose_source: PoseSource) -> FloatArray:
    """The points of ``scans`` in the reference frame of ``scans[centre]``.

    Parameters
    ----------
    scans : list of Scan
        Consecutive scans.
    centre : int
        Index in ``scans`` of the frame.
    pose_source : PoseSource
        Relative poses of the scans' references (the closed loop's current estimate).

    Returns
    -------
    ndarray, shape (N, 2)
    """
    poses = pose_source.poses(np.array([s.t_ref_s for s in scans]))
    parts = [
        transform_points(between(poses[centre], poses[i]), s.points_b)
        if i != centre
        else s.points_b
        for i, s in enumerate(scans)
    ]
    return np.concatenate(parts).reshape(-1, 2)
