"""The plugin seam of the design card: where the front end gets vehicle poses from.

GPS+AHRS, dead reckoning, the simulator's truth, the EKF and the factor graph all implement
:class:`PoseSource`. The front end (``features``) never imports any of them.
"""

from __future__ import annotations

from typing import Protocol, runtime_checkable

import numpy.typing as npt

from features.geometry import FloatArray

__all__ = ["PoseSource"]


@runtime_checkable
class PoseSource(Protocol):
    """Vehicle pose ``wTb`` (world East-North, yaw CCW from east) at given times."""

    def poses(self, t_s: npt.ArrayLike) -> FloatArray:
        """Poses of the vehicle body at times ``t_s``.

        Parameters
        ----------
        t_s : array_like, shape (N,)
            Unix times (s).

        Returns
        -------
        ndarray, shape (N, 3)
            ``(x_m, y_m, yaw_rad)`` per time.
        """
        ...

    def covariance(self, t_s: float) -> FloatArray | None:
        """3x3 covariance of the pose at ``t_s`` (m, m, rad), or None if the source has none."""
        ...
