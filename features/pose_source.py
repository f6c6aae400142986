"""The plugin seam of the design card: where the front end gets vehicle poses from.

GPS+AHRS, dead reckoning, the simulator's truth, the EKF and the factor graph all implement
:class:`PoseSource`. The front end (``features``) never imports any of them.
"""

from __future__ import annotations

from typing import Protocol, runtime_checkable

import numpy as np
import numpy.typing as npt

from sonarslam.features.geometry import FloatArray

__all__ = ["PoseSource", "BatchCovariances", "pose_covariances"]


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


@runtime_checkable
class BatchCovariances(Protocol):
    """A :class:`PoseSource` that also gives the covariances of many times in one call (the
    extractor asks for every stored beam's at each vote): the same values as
    :meth:`PoseSource.covariance` time by time."""

    def covariances(self, t_s: npt.ArrayLike) -> FloatArray | None:
        """Covariances at times ``t_s`` (N,), shape (N, 3, 3), or None if the source has none."""
        ...


def pose_covariances(source: PoseSource, t_s: npt.ArrayLike) -> FloatArray | None:
    """The pose covariances at times ``t_s`` (N,), shape (N, 3, 3) (m, m, rad), or None when
    the source has none at any of them: in one call where the source can
    (:class:`BatchCovariances`), else time by time."""
    t = np.atleast_1d(np.asarray(t_s, dtype=np.float64))
    if isinstance(source, BatchCovariances):
        return source.covariances(t)
    covs = [source.covariance(float(tk)) for tk in t]
    if any(c is None for c in covs):
        return None
    return np.stack([np.asarray(c, dtype=np.float64) for c in covs]).reshape(-1, 3, 3)
