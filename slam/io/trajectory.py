"""A timed sequence of poses with covariances (the output of every estimator, and a PoseSource),
and its files: TUM trajectories (``t x y z qx qy qz qw``, evo's reader and writer) named by what
they are (``ekf.tum``, ``isam2_smoothed.tum``, ``gps.tum``: :func:`trajectory_stem`) with the
pose covariances beside them (``ekf_cov.npz``: :func:`cov_file`).

Yaw and quaternions convert here only (:func:`yaw_to_quat_wxyz`, :func:`quat_wxyz_to_yaw`,
scipy's ``Rotation``).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import numpy.typing as npt
from evo.core.trajectory import PoseTrajectory3D
from evo.tools import file_interface
from scipy.spatial.transform import Rotation

from sonarslam.features.geometry import FloatArray, interpolate_poses

__all__ = [
    "Trajectory",
    "yaw_to_quat_wxyz",
    "quat_wxyz_to_yaw",
    "to_evo",
    "write_tum",
    "read_tum",
    "GPS_FILE",
    "TRUTH_FILE",
    "trajectory_stem",
    "cov_file",
    "with_samples_at",
    "write_trajectory_covariances",
    "read_trajectory_covariances",
    "with_covariances",
    "load_run_trajectory",
]


@dataclass(frozen=True, eq=False)
class Trajectory:
    """Body poses ``wTb`` at increasing times; implements :class:`sonarslam.features.pose_source.PoseSource`.

    Attributes
    ----------
    t_s : ndarray, shape (N,)
        Unix times (s), non-decreasing.
    poses_wTb : ndarray, shape (N, 3)
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
        yaw: FloatArray = object.__getattribute__(self, "_yaw_unwrapped")
        return interpolate_poses(t_s, self.t_s, self.poses_wTb, yaw)

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


def yaw_to_quat_wxyz(yaw_rad: npt.ArrayLike) -> FloatArray:
    """Quaternions ``(w, x, y, z)`` of rotations by ``yaw`` about z, shape (N, 4)."""
    yaw = np.atleast_1d(np.asarray(yaw_rad, dtype=np.float64))
    return np.asarray(Rotation.from_euler("z", yaw[:, None]).as_quat(scalar_first=True))


def quat_wxyz_to_yaw(quat_wxyz: npt.ArrayLike) -> FloatArray:
    """The yaw (rad, ``[-pi, pi]``) of quaternions ``(w, x, y, z)``, shape (N,): the first angle
    of the ``zyx`` Euler angles (a 3D trajectory projected on the plane)."""
    q = np.atleast_2d(np.asarray(quat_wxyz, dtype=np.float64))
    return np.asarray(Rotation.from_quat(q, scalar_first=True).as_euler("zyx")[:, 0])


def to_evo(trajectory: Trajectory) -> PoseTrajectory3D:
    """The planar trajectory as an evo ``PoseTrajectory3D`` (z = 0, yaw about z)."""
    yaw = trajectory.poses_wTb[:, 2]
    xyz = np.column_stack([trajectory.poses_wTb[:, :2], np.zeros_like(yaw)])
    return PoseTrajectory3D(
        positions_xyz=xyz,
        orientations_quat_wxyz=yaw_to_quat_wxyz(yaw),
        timestamps=trajectory.t_s.copy(),
    )


def write_tum(path: str | Path, trajectory: Trajectory) -> None:
    """Write ``t x y z qx qy qz qw`` (z = 0, yaw as a quaternion about z) with evo."""
    file_interface.write_tum_trajectory_file(str(path), to_evo(trajectory), confirm_overwrite=False)


def read_tum(path: str | Path) -> Trajectory:
    """Read a planar TUM trajectory written by :func:`write_tum` (or any TUM file, projected)."""
    traj = file_interface.read_tum_trajectory_file(str(path))
    return Trajectory(
        np.asarray(traj.timestamps, dtype=np.float64),
        np.column_stack([traj.positions_xyz[:, :2], quat_wxyz_to_yaw(traj.orientations_quat_wxyz)]),
    )


#: A run's reference: the GPS fixes inside the run with the AHRS heading (the ATE's reference).
GPS_FILE = "gps.tum"
#: A simulated run's true body poses inside the run.
TRUTH_FILE = "truth.tum"


def trajectory_stem(backend: str, name: str | None = None) -> str:
    """File stem of a run's trajectory: the back end's name (``ekf``), ``gps_ahrs`` for the
    ``gps`` baseline (``gps`` is the reference's), and ``<backend>_<name>`` for a back end's
    other trajectories (``isam2_smoothed``)."""
    stem = "gps_ahrs" if backend == "gps" else backend
    return stem if name is None else f"{stem}_{name}"


def cov_file(stem: str) -> str:
    """File of the pose covariances beside ``<stem>.tum``: ``<stem>_cov.npz``."""
    return f"{stem}_cov.npz"


def with_samples_at(trajectory: Trajectory, t_s: npt.ArrayLike) -> Trajectory:
    """``trajectory`` with poses added at the times ``t_s`` inside its span that it lacks.

    The added poses are the trajectory's own interpolation there (:meth:`Trajectory.poses`, as
    the ATE takes them), their covariances those of the sample before (as
    :meth:`Trajectory.covariance`). A file of it gives any tool that associates poses by
    timestamp (evo's ``evo_ape tum gps.tum ekf.tum``, 10 ms) the same pairs as the ATE.
    """
    t = np.unique(np.asarray(t_s, dtype=np.float64))
    t0, t1 = trajectory.span_s
    t = t[(t >= t0) & (t <= t1) & ~np.isin(t, trajectory.t_s)]
    if t.size == 0:
        return trajectory
    t_all = np.concatenate([trajectory.t_s, t])
    order = np.argsort(t_all, kind="stable")
    poses = np.concatenate([trajectory.poses_wTb, trajectory.poses(t)])[order]
    covs = None
    if trajectory.covs is not None:
        before = np.searchsorted(trajectory.t_s, t, side="right") - 1
        covs = np.concatenate([trajectory.covs, trajectory.covs[before]])[order]
    return Trajectory(t_all[order], poses, covs)


def write_trajectory_covariances(path: str | Path, trajectory: Trajectory) -> Path | None:
    """Write ``t_s`` (N,) and ``covs`` (N, 3, 3) of a trajectory to an ``.npz``.

    Returns the path, or None (nothing written) when the trajectory has no covariances.
    """
    if trajectory.covs is None:
        return None
    out = Path(path)
    np.savez_compressed(
        out,
        t_s=np.asarray(trajectory.t_s, dtype=np.float64),
        covs=np.asarray(trajectory.covs, dtype=np.float64),
    )
    return out


def read_trajectory_covariances(path: str | Path) -> tuple[FloatArray, FloatArray]:
    """``t_s`` (N,) (Unix s) and ``covs`` (N, 3, 3) from :func:`write_trajectory_covariances`."""
    with np.load(path) as data:
        t_s, covs = np.asarray(data["t_s"]), np.asarray(data["covs"])
    if covs.shape != (t_s.size, 3, 3):
        raise ValueError(f"{path}: covs (N, 3, 3) expected for {t_s.size} times, got {covs.shape}")
    return t_s, covs


def with_covariances(
    trajectory: Trajectory, t_s: FloatArray, covs: FloatArray, tol_s: float = 1e-6
) -> Trajectory:
    """``trajectory`` with the covariances of the same times attached.

    Raises ValueError when a pose has no covariance within ``tol_s`` of its time.
    """
    i = np.clip(np.searchsorted(t_s, trajectory.t_s), 1, max(t_s.size - 1, 1))
    i = np.where(np.abs(t_s[i - 1] - trajectory.t_s) <= np.abs(t_s[i] - trajectory.t_s), i - 1, i)
    if t_s.size == 0 or np.any(np.abs(t_s[i] - trajectory.t_s) > tol_s):
        raise ValueError("the covariances' times do not match the trajectory's")
    return Trajectory(trajectory.t_s, trajectory.poses_wTb, covs[i])


def load_run_trajectory(run_dir: str | Path, stem: str) -> Trajectory:
    """``<stem>.tum`` of a run directory, with its ``<stem>_cov.npz`` covariances when present."""
    run = Path(run_dir)
    tr = read_tum(run / f"{stem}.tum")
    cov_path = run / cov_file(stem)
    if cov_path.is_file():
        tr = with_covariances(tr, *read_trajectory_covariances(cov_path))
    return tr
