"""The factor graph's side of the seam: its smoothed trajectory as the front end's PoseSource.

The optimised nodes (their poses refreshed after iSAM2 updates) are densified by the odometry
chain between them (:func:`smoothed_poses`); past the newest optimised node the pose is that
node composed with the odometry since it, i.e. the back end's current pose. With
``ExtractorConfig.requery_poses`` the extractor re-reads the poses of its whole stored sector at
every vote, so every correction of the graph reaches the motion-distortion correction.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np
import numpy.typing as npt

from sonarslam.features.geometry import FloatArray, wrap_angle
from sonarslam.slam.model.motion import OdometryChain

__all__ = ["Rows", "NodeTable", "SmoothedPoseSource", "smoothed_poses"]


class Rows:
    """Rows of floats appended one at a time into a doubling numpy buffer."""

    def __init__(self, width: int, capacity: int = 1024) -> None:
        self._buf = np.empty((capacity, width))
        self.n = 0

    def append(self, row: Sequence[float] | FloatArray) -> None:
        if self.n == self._buf.shape[0]:
            self._buf = np.concatenate([self._buf, np.empty_like(self._buf)])
        self._buf[self.n] = row
        self.n += 1

    @property
    def rows(self) -> FloatArray:
        return self._buf[: self.n]


class NodeTable:
    """The optimised nodes of the graph: time, odometry chain value there, smoothed pose; and
    the marginal covariance of the newest node at each iSAM2 update (the filtered covariance)."""

    def __init__(self) -> None:
        self._t = Rows(1)
        self._odo = Rows(3)
        self._pose = Rows(3)
        self.anchor_t: list[float] = []
        self.anchor_cov: list[FloatArray] = []

    def __len__(self) -> int:
        return self._t.n

    def add(self, t_s: float, odo: FloatArray) -> None:
        """A node optimised for the first time: its time and the chain's value at that time."""
        self._t.append([t_s])
        self._odo.append(odo)
        self._pose.append([0.0, 0.0, 0.0])

    @property
    def t_s(self) -> FloatArray:
        return self._t.rows[:, 0]

    @property
    def odo(self) -> FloatArray:
        return self._odo.rows

    @property
    def poses(self) -> FloatArray:
        """Smoothed poses, writable in place by :meth:`refresh`, shape (N, 3)."""
        return self._pose.rows

    def refresh(self, t_from_s: float, pose_of_node: Callable[[int], FloatArray]) -> None:
        """Re-read the smoothed poses of the nodes at or after ``t_from_s``."""
        first = int(np.searchsorted(self.t_s, t_from_s, side="left"))
        poses = self._pose.rows
        for k in range(first, len(self)):
            poses[k] = pose_of_node(k)

    def add_anchor(self, t_s: float, cov: FloatArray) -> None:
        self.anchor_t.append(t_s)
        self.anchor_cov.append(cov)


def _carry(wTn: FloatArray, o_n: FloatArray, o_t: FloatArray) -> FloatArray:
    """``wTn * inverse(o_n) * o_t`` row by row, shapes (N, 3): a node carried by the odometry."""
    phi = wTn[:, 2] - o_n[:, 2]
    c, s = np.cos(phi), np.sin(phi)
    dx, dy = o_t[:, 0] - o_n[:, 0], o_t[:, 1] - o_n[:, 1]
    out = np.empty_like(o_t)
    out[:, 0] = wTn[:, 0] + c * dx - s * dy
    out[:, 1] = wTn[:, 1] + s * dx + c * dy
    out[:, 2] = wTn[:, 2] + o_t[:, 2] - o_n[:, 2]
    return out


def smoothed_poses(
    t_s: npt.ArrayLike,
    node_t_s: FloatArray,
    node_wTb: FloatArray,
    node_odo: FloatArray,
    odo_t: FloatArray,
) -> FloatArray:
    """Poses between smoothed nodes, shaped by the odometry (the pose source's rule).

    For ``t`` between nodes ``i`` and ``i + 1`` both nodes are carried to ``t`` by the odometry
    (``N_i * O(t_i)^-1 * O(t)``) and blended linearly in time: the result passes through both
    nodes and follows the odometry in between; if the odometry agrees with the nodes, it *is*
    the odometry. Past the newest node (and before the first) it is that node carried by the
    odometry.

    Parameters
    ----------
    t_s : array_like, shape (M,)
        Query times (Unix s).
    node_t_s : ndarray, shape (N,)
        Increasing node times, ``N >= 1``.
    node_wTb : ndarray, shape (N, 3)
        Smoothed node poses.
    node_odo : ndarray, shape (N, 3)
        Odometry chain ``O`` at the node times, yaw unwrapped.
    odo_t : ndarray, shape (M, 3)
        The odometry chain at the query times, yaw unwrapped
        (:meth:`sonarslam.slam.model.motion.OdometryChain.at`).

    Returns
    -------
    ndarray, shape (M, 3)
    """
    t = np.atleast_1d(np.asarray(t_s, dtype=np.float64))
    o_t = np.asarray(odo_t, dtype=np.float64).reshape(-1, 3)
    n = node_t_s.size
    i = np.clip(np.searchsorted(node_t_s, t, side="right") - 1, 0, n - 1)
    j = np.minimum(i + 1, n - 1)
    a = _carry(node_wTb[i], node_odo[i], o_t)
    b = _carry(node_wTb[j], node_odo[j], o_t)
    span = node_t_s[j] - node_t_s[i]
    w = np.where(span > 0.0, (t - node_t_s[i]) / np.where(span > 0.0, span, 1.0), 0.0)
    w = np.clip(w, 0.0, 1.0)
    out = a.copy()
    out[:, :2] += w[:, None] * (b[:, :2] - a[:, :2])
    out[:, 2] = wrap_angle(a[:, 2] + w * wrap_angle(b[:, 2] - a[:, 2]))
    return out


class SmoothedPoseSource:
    """PoseSource of the factor graph: its smoothed trajectory, densified by the odometry.

    Parameters
    ----------
    nodes : NodeTable
        The optimised nodes.
    chain : OdometryChain
        The back end's odometry chain.
    refresh : callable
        Brings the nodes' smoothed poses up to date (after an update) before a query.
    current_cov : callable
        The back end's current pose covariance.
    """

    def __init__(
        self,
        nodes: NodeTable,
        chain: OdometryChain,
        refresh: Callable[[], None],
        current_cov: Callable[[], FloatArray],
    ) -> None:
        self.nodes = nodes
        self.chain = chain
        self._refresh = refresh
        self._current_cov = current_cov

    def poses(self, t_s: npt.ArrayLike) -> FloatArray:
        """Body poses ``wTb`` at ``t_s`` (Unix s), shape (N, 3)."""
        self._refresh()
        n = self.nodes
        t = np.atleast_1d(np.asarray(t_s, dtype=np.float64))
        return smoothed_poses(t, n.t_s, n.poses, n.odo, self.chain.at(t))

    def covariance(self, t_s: float) -> FloatArray | None:
        """The filtered covariance at ``t_s``: the current one past the newest optimised node,
        else the iSAM2 marginal of the newest node optimised at or before ``t_s`` as it was
        when it was the newest (not propagated to ``t_s``)."""
        anchors = self.nodes.anchor_t
        if not anchors or t_s >= anchors[-1]:
            return self._current_cov()
        i = max(int(np.searchsorted(anchors, t_s, side="right")) - 1, 0)
        return self.nodes.anchor_cov[i]

    def covariances(self, t_s: npt.ArrayLike) -> FloatArray | None:
        """:meth:`covariance` at many times, shape (N, 3, 3)
        (:class:`sonarslam.features.pose_source.BatchCovariances`)."""
        t = np.atleast_1d(np.asarray(t_s, dtype=np.float64))
        anchors = self.nodes.anchor_t
        current = np.asarray(self._current_cov(), dtype=np.float64)
        out = np.repeat(current[None], t.size, axis=0)
        if anchors:
            past = t < anchors[-1]
            if past.any():
                i = np.maximum(np.searchsorted(anchors, t[past], side="right") - 1, 0)
                out[past] = np.stack([self.nodes.anchor_cov[k] for k in i])
        return out
