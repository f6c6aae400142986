"""The line feature handed from the front end to the back ends."""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import numpy.typing as npt

from sonarslam.features.geometry import FloatArray, line_frame_to_world, transform_points

__all__ = ["LineFeature", "check_mounting"]

#: Two mountings ``bTs`` closer than this in every component (m, rad) are the same.
MOUNTING_TOLERANCE = 1e-6


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
    bTs : ndarray, shape (3,) or None
        The sonar mounting ``(x_m, y_m, yaw_rad)`` in the body frame that the extractor placed
        ``wTr`` with (``wTr = wTb * bTs``), set by :class:`~sonarslam.features.extractor.LineExtractor`;
        a back end's line model must use the same (:func:`check_mounting`); ``lines.jsonl`` keeps
        it. None: not known (a line made by hand, or read from a file written without it), not
        checked.
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
    bTs: FloatArray | None = field(default=None, repr=False)

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
            **({} if self.bTs is None else {"bTs": np.asarray(self.bTs, dtype=float).tolist()}),
        }


def check_mounting(lines: Iterable[LineFeature], bTs: npt.ArrayLike, where: str) -> None:
    """Refuse a sonar mounting ``bTs`` that is not the one the lines were extracted with.

    A line is ``(rho, theta)`` in the sonar frame the extractor placed with its mounting; a
    line model with another mounting puts every landmark and pose off by the difference,
    without a word.

    Parameters
    ----------
    lines : iterable of LineFeature
        Lines whose ``bTs`` is None are not checked.
    bTs : array_like, shape (3,)
        The mounting ``(x_m, y_m, yaw_rad)`` given to the line model.
    where : str
        Names the parameter in the message (``"LandmarkAssociation(bTs=...)"``).

    Raises
    ------
    ValueError
        Naming ``where``, the mounting given and the lines' (the extractor's).
    """
    given = np.asarray(bTs, dtype=np.float64).reshape(3)
    for line in lines:
        if line.bTs is None:
            continue
        d = np.asarray(line.bTs, dtype=np.float64) - given
        d[2] = (d[2] + np.pi) % (2.0 * np.pi) - np.pi
        if np.max(np.abs(d)) > MOUNTING_TOLERANCE:
            fmt = np.array2string(given, precision=4, separator=", ")
            ext = np.array2string(np.asarray(line.bTs), precision=4, separator=", ")
            raise ValueError(
                f"{where}: sonar mounting bTs {fmt} (x_m, y_m, yaw_rad) is not the one the"
                f" lines were extracted with, {ext} (the LineExtractor's sonar_mounting,"
                " LineFeature.bTs): give the same mounting (Mounting.as_pose()) to both"
            )
