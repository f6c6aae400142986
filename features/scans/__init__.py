"""The scan matcher: motion-corrected scans of leading edges and their probabilistic
point-to-line ICP (MSISpIC, Mallios et al. 2014), a front end beside the line extractor."""

from features.scans.config import ScanConfig
from features.scans.icp import ReferenceLines, Registration, reference_lines, register
from features.scans.matcher import ScanMatcher
from features.scans.scan import Scan, ScanBuilder, submap_points

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
