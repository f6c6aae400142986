"""Settings of the scan matcher (:class:`sonarslam.features.scans.matcher.ScanMatcher`), units in names."""

from __future__ import annotations

from dataclasses import asdict, dataclass, replace
from typing import Any

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
        elsewhere, the motion correction). The README says how it was measured (GPS-free).
    revisit_cov_scale : float
        Factor on a revisit registration's covariance (submap to submap, from another pass):
        the same walls seen from elsewhere, at other ranges and incidences, whose echo bands'
        leading edges move with the view, which a floor measured on consecutive scans does not
        hold. The README says how the marina's was measured (GPS-free: short revisits against
        dead reckoning).
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

    beams_per_scan: int = 0
    run_gap_m: float = 1.0
    min_range_m: float = 1.0
    max_range_m: float | None = None
    intensity_threshold: float = 60.0
    submap_scans: int = 3
    normal_radius_m: float = 3.0
    min_normal_points: int = 3
    max_normal_thickness: float = 0.35
    corr_start_m: float = 3.0
    corr_end_m: float = 1.0
    iterations: int = 30
    kernel_k: float = 2.5
    min_sigma_m: float = 0.05
    degenerate_share: float = 0.05
    free_sigma: float = 100.0
    cov_scale: float = 4.0
    floor_sigma_m: float = 0.15
    floor_sigma_deg: float = 0.5
    revisit_cov_scale: float = 1.0
    starts_sigma: float = 1.5
    ambiguity_ratio: float = 0.9
    min_inliers: int = 15
    min_inlier_share: float = 0.4
    max_sigma_m: float = 1.0

    def __post_init__(self) -> None:
        if self.beams_per_scan < 0:
            raise ValueError(f"beams_per_scan must be >= 0, got {self.beams_per_scan}")
        if self.submap_scans < 1 or self.submap_scans % 2 == 0:
            raise ValueError(f"submap_scans must be odd and >= 1, got {self.submap_scans}")
        if self.max_range_m is not None and not self.max_range_m > self.min_range_m:
            raise ValueError(f"max_range_m must be > min_range_m, got {self.max_range_m}")
        if not 0.0 < self.corr_end_m <= self.corr_start_m:
            raise ValueError("need 0 < corr_end_m <= corr_start_m")
        positive = ("run_gap_m", "normal_radius_m", "kernel_k", "min_sigma_m", "free_sigma")
        if not (
            self.floor_sigma_m >= 0.0 and self.floor_sigma_deg >= 0.0 and self.starts_sigma >= 0.0
        ):
            raise ValueError("floor_sigma_m, floor_sigma_deg and starts_sigma must be >= 0")
        for name in (*positive, "cov_scale", "max_sigma_m", "revisit_cov_scale"):
            if not getattr(self, name) > 0.0:
                raise ValueError(f"{name} must be > 0, got {getattr(self, name)}")
        if self.iterations < 1 or self.min_inliers < 3 or self.min_normal_points < 2:
            raise ValueError("iterations >= 1, min_inliers >= 3, min_normal_points >= 2")
        if not 0.0 <= self.min_inlier_share <= 1.0 or not 0.0 < self.degenerate_share < 1.0:
            raise ValueError("min_inlier_share in [0, 1], degenerate_share in (0, 1)")
        if not 0.0 < self.max_normal_thickness <= 1.0:
            raise ValueError("max_normal_thickness must be in (0, 1]")

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)

    def replace(self, **changes: Any) -> ScanConfig:
        """A copy with some fields changed."""
        return replace(self, **changes)
