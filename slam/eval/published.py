"""Published accuracy on the marina, the rows our tables stand beside.

Mallios, Ridao, Ribas, Hernandez, "Scan matching SLAM in underwater environments", Autonomous
Robots 36:181-198, 2014, Table 2: ATE against GPS (m) by the protocol of :mod:`sonarslam.slam.eval.ate`.
"""

from __future__ import annotations

from typing import Any

__all__ = ["PUBLISHED"]

#: Published ATE against GPS on the marina (m): Mallios, Ridao, Ribas, Hernandez, "Scan
#: matching SLAM in underwater environments", Autonomous Robots 36:181-198, 2014, Table 2.
PUBLISHED: list[dict[str, Any]] = [
    {"method": "dead reckoning (DVL + MTi)", "mean": 17.46, "sd": 11.47, "min": 0.09, "max": 45.42},
    {
        "method": "scan matching (Hernández 2009)",
        "mean": 3.99,
        "sd": 2.11,
        "min": 0.03,
        "max": 8.49,
    },
    {
        "method": "EKF-SLAM, Hough lines (Ribas 2008)",
        "mean": 1.91,
        "sd": 1.32,
        "min": 0.01,
        "max": 5.08,
    },
    {
        "method": "MSISpIC, pose-based scan matching",
        "mean": 1.90,
        "sd": 1.09,
        "min": 0.01,
        "max": 4.93,
    },
]
