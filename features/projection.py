"""Sonar bins to world points with any pose source (for maps, pictures and calibration)."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from sonarslam.features.geometry import FloatArray, compose
from sonarslam.features.pose_source import PoseSource
from sonarslam.sonar.beam import Mounting, SonarBeam, SonarHead, beam_bin_size_m

__all__ = ["beam_points", "project_beams"]


def beam_points(
    beams: Sequence[SonarBeam], head: SonarHead, min_intensity: int = 1
) -> tuple[np.ndarray, FloatArray, FloatArray]:
    """The bins at or above ``min_intensity`` of every beam.

    Returns
    -------
    beam_index : ndarray of int, shape (N,)
        Index in ``beams`` of each bin.
    range_m : ndarray, shape (N,)
        Range of the bin (m), with its beam's own bin size
        (:func:`~sonarslam.sonar.beam.beam_bin_size_m`).
    bearing_rad : ndarray, shape (N,)
        Bearing in the sonar frame (:meth:`SonarHead.bearing_rad`).
    """
    if not beams:
        return np.zeros(0, np.int64), np.zeros(0), np.zeros(0)
    stack = np.stack([b.intensities for b in beams])
    bi, bins = np.nonzero(stack >= min_intensity)
    bi = bi.astype(np.int64)
    angles = np.array([b.transducer_angle_rad for b in beams])
    if hasattr(beams, "bin_size_m"):  # a BeamSeries: its array, or None (the head's)
        own = beams.bin_size_m
        sizes = None if own is None else own[bi]
    else:
        sizes = np.array([beam_bin_size_m(b, head) for b in beams])[bi]
    return (
        bi,
        head.bin_range_m(bins, sizes),
        head.bearing_rad(angles[bi]),
    )


def project_beams(
    beams: Sequence[SonarBeam],
    head: SonarHead,
    sonar_mounting: Mounting,
    pose_source: PoseSource,
    min_intensity: int = 1,
) -> tuple[FloatArray, FloatArray]:
    """World points of the bins of ``beams``, each with the pose at its beam's time.

    Returns
    -------
    points_w : ndarray, shape (N, 2)
        East-North (m).
    t_s : ndarray, shape (N,)
        Beam time of each point (Unix s).
    """
    bi, r, bearing = beam_points(beams, head, min_intensity)
    t = np.array([b.t for b in beams])
    wTs = compose(pose_source.poses(t), sonar_mounting.as_pose())[bi]
    ang = wTs[:, 2] + bearing
    pts = np.column_stack([wTs[:, 0] + r * np.cos(ang), wTs[:, 1] + r * np.sin(ang)])
    return pts, t[bi]
