"""Absolute trajectory error by the protocol of Mallios et al. 2014 (the marina's published table).

At every GPS fix inside the trajectory's time span, the distance between the GPS position and
the estimate interpolated at that time; no alignment of any kind.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

from datasets.records import GpsSeries
from features.geometry import FloatArray
from slam.io.trajectory import Trajectory

__all__ = ["AteResult", "ate_against_gps", "ate_errors"]


@dataclass(frozen=True)
class AteResult:
    """ATE statistics (m) over ``n`` GPS fixes."""

    ate_mean_m: float
    ate_sd_m: float
    ate_min_m: float
    ate_max_m: float
    ate_rmse_m: float
    ate_n: int

    def as_dict(self) -> dict[str, float | int]:
        return asdict(self)


def ate_errors(trajectory: Trajectory, gps: GpsSeries) -> tuple[FloatArray, FloatArray]:
    """Times (s) and position errors (m) at the GPS fixes inside the trajectory's span."""
    t0, t1 = trajectory.span_s
    inside = (gps.t >= t0) & (gps.t <= t1)
    est = trajectory.poses(gps.t[inside])[:, :2]
    return gps.t[inside], np.hypot(*(est - gps.en_m[inside]).T)


def ate_against_gps(trajectory: Trajectory, gps: GpsSeries) -> AteResult:
    """The ATE of ``trajectory`` against ``gps``; raises ValueError when no fix is inside."""
    _, e = ate_errors(trajectory, gps)
    if e.size == 0:
        raise ValueError("no GPS fix inside the trajectory's time span")
    return AteResult(
        ate_mean_m=float(e.mean()),
        ate_sd_m=float(e.std(ddof=1)) if e.size > 1 else 0.0,
        ate_min_m=float(e.min()),
        ate_max_m=float(e.max()),
        ate_rmse_m=float(np.sqrt(np.mean(e**2))),
        ate_n=int(e.size),
    )
