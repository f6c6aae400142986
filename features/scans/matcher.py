"""The scan matcher: the second front end, beside the line extractor, on the same seam.

It gets the beams and, through :class:`sonarslam.features.pose_source.PoseSource`, the closed loop's own
poses (never a back end's internals). It builds motion-corrected scans
(:mod:`sonarslam.features.scans.scan`) and registers them (:mod:`sonarslam.features.scans.icp`):

* each new scan onto the one before it (:meth:`ScanMatcher.consecutive`), from the relative
  pose of the pose source;
* any older scan ``j`` with the newest ``k`` (:meth:`ScanMatcher.register`), as two submaps of
  ``submap_scans`` scans each, from a relative pose the caller gives: a back end proposes these
  revisits from its own marginals.

Each result is a relative pose ``jTk`` of the scans' reference body frames with its 3x3
covariance and the directions it constrains (:class:`sonarslam.features.scans.icp.Registration`).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import numpy.typing as npt

from sonarslam.features.geometry import FloatArray, between
from sonarslam.features.pose_source import PoseSource
from sonarslam.features.scans.config import ScanConfig
from sonarslam.features.scans.icp import (
    ReferenceLines,
    Registration,
    reference_lines,
    register,
    register_from,
)
from sonarslam.features.scans.scan import Scan, ScanBuilder, submap_points
from sonarslam.sonar.beam import Mounting, SonarBeam, SonarHead

__all__ = ["ScanMatcher"]


class ScanMatcher:
    """Scans from beams, and their registration (module docstring).

    Parameters
    ----------
    config : ScanConfig
    head : SonarHead
    sonar_mounting : Mounting
    pose_source : PoseSource
        The closed loop's poses: motion correction, submaps, consecutive guesses.
    """

    def __init__(
        self, config: ScanConfig, head: SonarHead, sonar_mounting: Mounting, pose_source: PoseSource
    ) -> None:
        self.config = config
        self.pose_source = pose_source
        self.builder = ScanBuilder(config, head, sonar_mounting, pose_source)
        self.scans: list[Scan] = []
        self._lines: dict[int, ReferenceLines] = {}  # single scans, by index
        self._submap_lines: dict[int, ReferenceLines] = {}  # old submaps, by centre
        self._frozen: dict[int, FloatArray] = {}  # complete submaps' points, by centre

    def add(self, beam: SonarBeam) -> Scan | None:
        """Take one beam; the scan it completes (kept), else None."""
        scan = self.builder.add(beam)
        if scan is not None:
            self.scans.append(scan)
            centre = scan.index - self.config.submap_scans // 2
            if centre >= 0 and centre - self.config.submap_scans // 2 >= 0:
                # the submap around ``centre`` is complete: its scans placed with the pose
                # source's relative poses now, while they are recent (the odometry's own,
                # locally right); later loop closures that bend the estimate leave it whole
                self._frozen[centre] = self.submap(centre)
        return scan

    def _scan_lines(self, i: int) -> ReferenceLines:
        if i not in self._lines:
            self._lines[i] = reference_lines(self.scans[i].points_b, self.config)
        return self._lines[i]

    def consecutive(self, k: int | None = None) -> Registration | None:
        """Scan ``k`` (the newest by default) registered onto scan ``k - 1``: ``(k-1)Tk``;
        None for the first scan."""
        k = len(self.scans) - 1 if k is None else k
        if k < 1:
            return None
        a, b = self.scans[k - 1], self.scans[k]
        poses = self.pose_source.poses(np.array([a.t_ref_s, b.t_ref_s]))
        return register(
            self._scan_lines(k - 1), b.points_b, between(poses[0], poses[1]), self.config
        )

    def submap_window(self, i: int) -> tuple[int, int]:
        """``(first, last)`` scan indices of the submap around scan ``i``: centred on it, shifted
        back at the newest end (the scans after it do not exist yet)."""
        h = self.config.submap_scans // 2
        last = min(i + h, len(self.scans) - 1)
        first = max(last - 2 * h, 0)
        return first, min(first + 2 * h, len(self.scans) - 1)

    def submap(self, i: int) -> FloatArray:
        """The submap around scan ``i`` in its reference frame, shape (N, 2): frozen when it
        was complete, else placed with the pose source's current relative poses."""
        if i in self._frozen:
            return self._frozen[i]
        first, last = self.submap_window(i)
        return submap_points(self.scans[first : last + 1], i - first, self.pose_source)

    def register(
        self, j: int, k: int, guess_jTk: npt.ArrayLike, guess_cov: npt.ArrayLike | None = None
    ) -> Registration:
        """Submap ``k`` registered onto submap ``j`` from ``guess_jTk``: ``jTk``; with its
        covariance ``guess_cov`` (3, 3), from several starts
        (:func:`sonarslam.features.scans.icp.register_from`). Its covariance is scaled by
        ``revisit_cov_scale``.

        The reference submap's lines are kept while its window is complete (an old scan).
        """
        complete = self.submap_window(j)[1] - self.submap_window(j)[0] + 1 == min(
            self.config.submap_scans, len(self.scans)
        ) and j + self.config.submap_scans // 2 < len(self.scans)
        if complete and j in self._submap_lines:
            ref = self._submap_lines[j]
        else:
            ref = reference_lines(self.submap(j), self.config)
            if complete:
                self._submap_lines[j] = ref
        guess = np.asarray(guess_jTk, dtype=np.float64)
        if guess_cov is None:
            reg = register(ref, self.submap(k), guess, self.config)
        else:
            reg = register_from(ref, self.submap(k), guess, np.asarray(guess_cov), self.config)
        if self.config.revisit_cov_scale == 1.0:
            return reg
        return replace(reg, cov=reg.cov * self.config.revisit_cov_scale)
