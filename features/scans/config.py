"""Settings of the scan matcher (:class:`sonarslam.features.scans.matcher.ScanMatcher`), units in names."""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, replace
from typing import Any

from sonarslam.settings import bounded, check_fields

__all__ = ["ScanConfig"]


@dataclass(frozen=True)
class ScanConfig:
    """Settings of the scans and of their registration (probabilistic point-to-line ICP).

    Scans (:mod:`sonarslam.features.scans.scan`):

    Attributes
    ----------
    beams_per_scan : int
        Beams of one scan; 0: one full turn of the head (``round(2 pi / step)``).
    run_gap_m, min_range_m, max_range_m, intensity_threshold
        The leading edge of each run of returns of a beam is a scan point
        (:func:`sonarslam.sonar.segmentation.leading_edge_bins`): runs are chains of returns with gaps
        under ``run_gap_m`` (m); bins nearer than ``min_range_m`` or farther than
        ``max_range_m`` (m, None: all) are ignored; a raw beam's returns are its bins at or above
        ``intensity_threshold`` (masks: every non-zero bin).
    submap_scans : int
        A revisit registers two submaps of this many consecutive scans each (odd: the scan and
        its neighbours, motion-corrected into the middle scan's frame; the newest scan's submap
        takes the scans before it). Consecutive scans are registered one to one.

    Registration (:func:`sonarslam.features.scans.icp.register`):

    normal_radius_m : float
        The reference scan's points within this of a point fit its local line (m).
    min_normal_points : int
        A reference point needs this many neighbours (itself included) for a line.
    max_normal_thickness : float
        ... and the ratio of the smaller to the larger principal sigma of its neighbours at
        most this (a line, not a blob).
    corr_start_m, corr_end_m : float
        Largest point-to-point distance of a correspondence (m) at the first iteration and,
        shrinking geometrically, from ``iterations // 2`` on.
    iterations : int
        Gauss-Newton iterations at most.
    kernel_k : float
        Width of the Cauchy weight on the point-to-line residual, in residual sigmas (the
        sigma is the residuals' own, by their median absolute deviation).
    min_sigma_m : float
        The residual sigma is at least this (m): the leading edge's own quantisation.
    degenerate_share : float
        A direction of ``(x, y, L yaw)`` (``L`` the inliers' RMS distance from the scan's
        origin) is constrained when its information is at least this share of what the inliers
        would give if all of them faced it: a corridor's direction along its walls is not, and
        is left to the odometry (its step is not taken, its variance is ``free_sigma``).
    free_sigma : float
        Sigma of an unconstrained direction in the measurement's covariance (m; rad times L).
    cov_scale : float
        Factor on the Hessian's covariance ``sigma^2 (J^T W J)^-1``: the residuals of points of
        one wall are not independent (its roughness and echo band are shared), which the
        Hessian does not know.
    floor_sigma_m, floor_sigma_deg : float
        A systematic error added in the constrained directions, per axis (m) and in yaw (deg):
        what the scans' own noise does not explain (the same wall's echo band seen from
        elsewhere, the motion correction). docs/scan-matching.md says how it was chosen
        (GPS-free).
    revisit_cov_scale : float
        Factor on a revisit registration's covariance (submap to submap, from another pass):
        the same walls seen from elsewhere, at other ranges and incidences, whose echo bands'
        leading edges move with the view, which a floor measured on consecutive scans does not
        hold. docs/scan-matching.md says how the marina's was chosen (GPS-free: short revisits
        against dead reckoning).
    starts_sigma : float
        With the guess's covariance given (:meth:`sonarslam.features.scans.matcher.ScanMatcher.register`
        for revisits), ICP also starts from the guess moved by this many sigmas either way
        along the two largest principal directions of that covariance, when their sigma is
        beyond ``corr_end_m``; the solution with the most weight wins.
    ambiguity_ratio : float
        ... and it is rejected as ambiguous when another start converges more than
        ``corr_end_m`` away with at least this share of its weight (a corridor, a row of
        piers).
    min_inliers : int
        A registration is accepted with at least this many inliers ...
    min_inlier_share : float
        ... that are at least this share of the moving scan's points ...
    max_sigma_m : float
        ... and a residual sigma at most this (m).
    """

    beams_per_scan: int = bounded(0, 0, 1e6)
    run_gap_m: float = bounded(1.0, 0.0, math.inf, low_open=True)
    min_range_m: float = bounded(1.0, 0.0, 1e4)
    max_range_m: float | None = bounded(None, 0.0, 1e4)
    intensity_threshold: float = bounded(60.0, 0.0, 255.0)
    submap_scans: int = bounded(3, 1, 1001)
    normal_radius_m: float = bounded(3.0, 0.0, math.inf, low_open=True)
    min_normal_points: int = bounded(3, 2, 1e6)
    max_normal_thickness: float = bounded(0.35, 0.0, 1.0, low_open=True)
    corr_start_m: float = bounded(3.0, 0.0, math.inf, low_open=True)
    corr_end_m: float = bounded(1.0, 0.0, math.inf, low_open=True)
    iterations: int = bounded(30, 1, 1000)
    kernel_k: float = bounded(2.5, 0.0, math.inf, low_open=True)
    min_sigma_m: float = bounded(0.05, 0.0, math.inf, low_open=True)
    degenerate_share: float = bounded(0.05, 0.0, 1.0, low_open=True, high_open=True)
    free_sigma: float = bounded(100.0, 0.0, math.inf, low_open=True)
    cov_scale: float = bounded(4.0, 0.0, math.inf, low_open=True)
    floor_sigma_m: float = bounded(0.15, 0.0, math.inf)
    floor_sigma_deg: float = bounded(0.5, 0.0, 180.0)
    revisit_cov_scale: float = bounded(1.0, 0.0, math.inf, low_open=True)
    starts_sigma: float = bounded(1.5, 0.0, math.inf)
    ambiguity_ratio: float = bounded(0.9, 0.0, math.inf)
    min_inliers: int = bounded(15, 3, 1e9)
    min_inlier_share: float = bounded(0.4, 0.0, 1.0)
    max_sigma_m: float = bounded(1.0, 0.0, math.inf, low_open=True)

    def __post_init__(self) -> None:
        check_fields(self)
        if self.submap_scans % 2 == 0:
            raise ValueError(f"submap_scans must be odd, got {self.submap_scans}")
        if self.max_range_m is not None and not self.max_range_m > self.min_range_m:
            raise ValueError(f"max_range_m must be > min_range_m, got {self.max_range_m}")
        if not self.corr_end_m <= self.corr_start_m:
            raise ValueError(f"corr_end_m must be <= corr_start_m, got {self.corr_end_m}")

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)

    def replace(self, **changes: Any) -> ScanConfig:
        """A copy with some fields changed."""
        return replace(self, **changes)
