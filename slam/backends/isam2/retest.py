"""Line associations re-tested when a loop closes (``GraphConfig.retest_window_s``).

The landmark layer decides each line observation once, at the estimate of its vote; the graph
keeps the decision as a factor. When the estimate has moved beyond what a recent line was
associated at (a revisit, a loop of lines: the vote's pose now, its node's estimate composed with
the vote's offset from it, beyond the chi2(3) 0.99 gate of the pose covariance the association
was decided with), the line factor (of the last ``retest_window_s``) is tested again at the new
estimate (the poses are compared every :data:`CHECK_PERIOD_S`): its residual against the joint
marginal of its node and landmark (the individual compatibility test of the association,
:func:`sonarslam.slam.mapping.association.individual_compatibility`, at the estimate now:
``d^2 = b^T (I + A Sigma A^T)^-1 b`` with ``A``, ``b`` the factor's whitened Jacobian and
residual, without its robust kernel, and ``Sigma`` the marginal), and a factor beyond the
association gate is removed from iSAM2 (``removeFactorIndices``) and from the graph's records; its
observation is then unassociated. A removed factor is not re-associated with another landmark.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import gtsam
import numpy as np
from gtsam.symbol_shorthand import L, X
from scipy.stats import chi2

from sonarslam.features.geometry import FloatArray, compose, wrap_angle
from sonarslam.features.line import LineFeature
from sonarslam.slam.backends.isam2.graph_io import FactorRecord, pose_of

__all__ = ["CHECK_PERIOD_S", "LineFactor", "LineRetest"]

#: The recent votes' poses are compared with their estimate at most this often (s of data).
CHECK_PERIOD_S = 5.0


@dataclass
class LineFactor:
    """A line factor of the graph: its record, node, landmark, observation and time (Unix s),
    the vote's body pose in its node's frame ``kTb`` (3,), the vote's body pose ``wTb`` (3,) and
    its covariance (3, 3, world ``(x_m, y_m, yaw_rad)``) when it was associated, and its index in
    iSAM2 once added (None before)."""

    record: FactorRecord
    node: int
    landmark: int
    feature: LineFeature
    t_s: float
    kTb: FloatArray
    wTb: FloatArray
    cov_w: FloatArray
    index: int | None = None


class LineRetest:
    """The bookkeeping and the test (module docstring).

    Parameters
    ----------
    window_s : float
        The line factors this recent (s) are re-tested.
    gate_probability : float
        The association gate (chi2(2)) a re-tested factor must pass.
    """

    def __init__(self, window_s: float, gate_probability: float) -> None:
        self.window_s = float(window_s)
        self._gate = float(chi2.ppf(gate_probability, 2))
        self._moved = float(chi2.ppf(0.99, 3))
        self._checked_s = -np.inf
        self._recent: list[LineFactor] = []
        self._by_record: dict[int, LineFactor] = {}
        #: observations whose factor was removed: ``id(feature)`` -> None (their new landmark)
        self.revised: dict[int, int | None] = {}
        self.stats = {"retest_runs": 0, "retest_factors": 0, "retest_removed": 0}

    def added(
        self,
        record: FactorRecord,
        node: int,
        landmark: int,
        f: LineFeature,
        kTb: FloatArray,
        wTb: FloatArray,
        cov_w: FloatArray,
    ) -> None:
        """A line factor into the pending ones (:class:`LineFactor`)."""
        item = LineFactor(record, node, landmark, f, float(f.t), kTb, wTb, cov_w)
        self._recent.append(item)
        self._by_record[id(record)] = item

    def indexed(self, records: list[FactorRecord], indices: list[int]) -> None:
        """The iSAM2 indices of an update's new factors, in the order they were added."""
        for record, index in zip(records, indices, strict=True):
            item = self._by_record.get(id(record))
            if item is not None:
                item.index = int(index)

    def _moved_beyond(self, isam: gtsam.ISAM2, item: LineFactor) -> bool:
        """Whether the vote's pose now is beyond the gate of its covariance then."""
        wTb = compose(pose_of(isam.calculateEstimatePose2(X(item.node))), item.kTb)
        d = wTb - item.wTb
        d[2] = float(wrap_angle(d[2]))
        try:
            return bool(d @ np.linalg.solve(item.cov_w, d) > self._moved)
        except np.linalg.LinAlgError:
            return False

    def run(self, isam: gtsam.ISAM2, t_now_s: float) -> list[LineFactor]:
        """Test the recent line factors whose vote's pose moved (module docstring) at iSAM2's
        estimate with its marginals; the ones to remove (forgotten here)."""
        if t_now_s - self._checked_s < CHECK_PERIOD_S:
            return []
        self._checked_s = t_now_s
        self._recent = [i for i in self._recent if i.t_s >= t_now_s - self.window_s]
        self._by_record = {id(i.record): i for i in self._recent}
        moved = [i for i in self._recent if i.index is not None and self._moved_beyond(isam, i)]
        if not moved:
            return []
        self.stats["retest_runs"] += 1
        values = isam.calculateEstimate()
        removed = []
        for item in moved:
            # re-tested once per move: the next re-test needs a move beyond the same gate again
            item.wTb = compose(pose_of(isam.calculateEstimatePose2(X(item.node))), item.kTb)
            self.stats["retest_factors"] += 1
            factor = replace(item.record, robust=None).to_gtsam()
            lin = factor.linearize(values)
            A, b = lin.jacobian()
            keys = [X(item.node), L(item.landmark)]
            joint = isam.jointMarginalCovariance(keys).fullMatrix()
            # the Jacobian's columns follow the factor's keys (node, landmark, calibration...)
            k = joint.shape[0]
            S = np.eye(b.size) + A[:, :k] @ joint @ A[:, :k].T
            d2 = float(b @ np.linalg.solve(S, b))
            if d2 > self._gate:
                removed.append(item)
        for item in removed:
            self._recent.remove(item)
            del self._by_record[id(item.record)]
            self.revised[id(item.feature)] = None
        self.stats["retest_removed"] += len(removed)
        return removed
