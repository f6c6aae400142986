"""The line feature handed from the front end to the back ends."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from sonarslam.features.geometry import FloatArray, line_frame_to_world, transform_points

__all__ = ["LineFeature"]


@dataclass(frozen=True, eq=False)
class LineFeature:
    """A line extracted in the reference frame R of one vote (design.md steps 3-7).

    Attributes
    ----------
    t : float
        Time of the newest beam, whose sensor pose is frame R (Unix s).
    wTr : ndarray, shape (3,)
        Pose of frame R (the sonar head) in the world used at extraction ``(x_m, y_m, yaw_rad)``.
    rho_m, theta_rad : float
        The line in frame R, normalised (``rho >= 0``, ``theta`` in ``[-pi, pi)``).
    cov : ndarray, shape (2, 2)
        Covariance of ``(rho_m, theta_rad)``.
    votes : int
        Votes of the winning cell.
    endpoints_r : ndarray, shape (2, 2)
        Ends of the segment seen by the voters, rows of points in frame R (m).
    n_voters : int
        Bins that voted for the line (removed from the store after the vote).
    z : ndarray, shape (2,)
        Property: ``(rho_m, theta_rad)``, the measurement a back end takes with ``cov``.
    """

    t: float
    wTr: FloatArray
    rho_m: float
    theta_rad: float
    cov: FloatArray
    votes: int
    endpoints_r: FloatArray = field(repr=False)
    n_voters: int = 0

    @property
    def z(self) -> FloatArray:
        """The measurement ``(rho_m, theta_rad)`` in frame R, shape (2,)."""
        return np.array([self.rho_m, self.theta_rad])

    def line_world(self) -> FloatArray:
        """The line in the world frame with the extraction pose, shape (2,)."""
        return line_frame_to_world(self.z, self.wTr)[0]

    def endpoints_world(self) -> FloatArray:
        """Segment ends in the world frame, shape (2, 2) (m)."""
        return transform_points(self.wTr, self.endpoints_r)

    def to_json(self) -> dict[str, Any]:
        """One ``lines.jsonl`` object (docs/outputs.md)."""
        return {
            "t": float(self.t),
            "x": float(self.wTr[0]),
            "y": float(self.wTr[1]),
            "yaw": float(self.wTr[2]),
            "rho": float(self.rho_m),
            "theta": float(self.theta_rad),
            "cov": np.asarray(self.cov, dtype=float).tolist(),
            "votes": int(self.votes),
            "n_voters": int(self.n_voters),
            "endpoints": self.endpoints_world().tolist(),
        }
