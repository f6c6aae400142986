"""The scan matcher: motion-corrected scans of leading edges and their probabilistic
point-to-line ICP (MSISpIC, Mallios et al. 2014), a front end beside the line extractor."""

from sonarslam.features.scans.config import ScanConfig
from sonarslam.features.scans.icp import ReferenceLines, Registration, reference_lines, register
from sonarslam.features.scans.matcher import ScanMatcher
from sonarslam.features.scans.scan import Scan, ScanBuilder, submap_points

__all__ = [
    "ScanConfig",
    "ReferenceLines",
    "Registration",
    "reference_lines",
    "register",
    "ScanMatcher",
    "Scan",
    "ScanBuilder",
    "submap_points",
]
