"""A timed sequence of poses with covariances: the output of every estimator, and a PoseSource."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import numpy.typing as npt
from evo.core.trajectory import PoseTrajectory3D
from evo.tools import file_interface

from features.geometry import FloatArray, interpolate_poses

__all__ = ["Trajectory", "write_tum", "read_tum"]


@dataclass(frozen=True, eq=False)
class Trajectory:
    """Body poses ``wTb`` at increasing times; implements :class:`features.pose_source.PoseSource`.

    Attributes
    ----------
    t_s : ndarray, shape (N,)
        Unix times (s), non-decreasing.
    poses : ndarray, shape (N, 3)
        ``(x_m, y_m, yaw_rad)`` in local East-North.
    covs : ndarray, shape (N, 3, 3) or None
        Pose covariances.
    """

    t_s: FloatArray
    poses_wTb: FloatArray
    covs: FloatArray | None = None

    def __post_init__(self) -> None:
        if self.t_s.ndim != 1 or self.poses_wTb.shape != (self.t_s.size, 3):
            raise ValueError(
                f"t_s (N,) and poses (N, 3) expected, got {self.t_s.shape}, {self.poses_wTb.shape}"
            )
        if self.t_s.size and np.any(np.diff(self.t_s) < 0):
            raise ValueError("trajectory times must not decrease")
        # unwrapped yaw, computed once: poses() is called at every vote of the extractor
        object.__setattr__(self, "_yaw_unwrapped", np.unwrap(self.poses_wTb[:, 2]))

    @property
    def span_s(self) -> tuple[float, float]:
        return float(self.t_s[0]), float(self.t_s[-1])

    def poses(self, t_s: npt.ArrayLike) -> FloatArray:
        """Poses interpolated at ``t_s`` (ends held outside the span), shape (M, 3)."""
        return interpolate_poses(t_s, self.t_s, self.poses_wTb, self._yaw_unwrapped)  # type: ignore[attr-defined]

    def covariance(self, t_s: float) -> FloatArray | None:
        """Covariance of the last sample at or before ``t_s`` (3, 3), or None."""
        if self.covs is None:
            return None
        i = int(np.clip(np.searchsorted(self.t_s, t_s, side="right") - 1, 0, self.t_s.size - 1))
        return np.asarray(self.covs[i])

    def clip(self, t0_s: float, t1_s: float) -> Trajectory:
        keep = (self.t_s >= t0_s) & (self.t_s <= t1_s)
        return Trajectory(
            self.t_s[keep], self.poses_wTb[keep], None if self.covs is None else self.covs[keep]
        )


def write_tum(path: str | Path, trajectory: Trajectory) -> None:
    """Write ``t x y z qx qy qz qw`` (z = 0, yaw as a quaternion about z) with evo."""
    yaw = trajectory.poses_wTb[:, 2]
    quat_wxyz = np.stack(
        [np.cos(yaw / 2), np.zeros_like(yaw), np.zeros_like(yaw), np.sin(yaw / 2)], axis=1
    )
    xyz = np.column_stack([trajectory.poses_wTb[:, :2], np.zeros_like(yaw)])
    traj = PoseTrajectory3D(
        positions_xyz=xyz, orientations_quat_wxyz=quat_wxyz, timestamps=trajectory.t_s
    )
    file_interface.write_tum_trajectory_file(str(path), traj, confirm_overwrite=False)


def read_tum(path: str | Path) -> Trajectory:
    """Read a planar TUM trajectory written by :func:`write_tum` (or any TUM file, projected)."""
    traj = file_interface.read_tum_trajectory_file(str(path))
    q = traj.orientations_quat_wxyz
    yaw = np.arctan2(
        2 * (q[:, 0] * q[:, 3] + q[:, 1] * q[:, 2]), 1 - 2 * (q[:, 2] ** 2 + q[:, 3] ** 2)
    )
    return Trajectory(
        np.asarray(traj.timestamps, dtype=np.float64),
        np.column_stack([traj.positions_xyz[:, :2], yaw]),
    )
