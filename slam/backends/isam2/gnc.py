"""A joint choice of inliers among uncertain factors: graduated non-convexity with a truncated
least-squares cost (GNC-TLS: Yang, Antonante, Tzoumas, Carlone 2020, "Graduated non-convexity
for robust spatial perception", eqs. 12-14).

GTSAM's ``GncLMOptimizer`` cannot clone this package's ``CustomFactor``s, so the loop is here.
The candidates are factor records (:class:`sonarslam.slam.backends.isam2.graph_io.FactorRecord`)
with their Gaussian noise (GNC's loss replaces any kernel); every other factor is a known
inlier. With ``r^2`` a candidate's squared Mahalanobis residual and ``c^2`` the truncation, its
weight is 1 for ``r^2 <= mu / (mu + 1) c^2``, 0 beyond ``(mu + 1) / mu c^2`` and
``c / r sqrt(mu (mu + 1)) - mu`` between; a Levenberg-Marquardt pass at the weights
(``cov / w``), ``mu`` from ``c^2 / (2 max r^2 - c^2)`` times 1.4 each step until the weights
settle at 0 or 1.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import gtsam
import numpy as np

from sonarslam.features.geometry import FloatArray
from sonarslam.slam.backends.isam2.graph_io import FactorRecord

__all__ = ["GncResult", "gnc_tls"]


@dataclass(frozen=True, eq=False)
class GncResult:
    """The result of :func:`gnc_tls`.

    Attributes
    ----------
    values : gtsam.Values
        The optimum at the final weights.
    weights : ndarray, shape (n,)
        Each candidate's weight (0 or 1 once settled; inliers above 0.5).
    steps : int
        GNC steps taken.
    """

    values: gtsam.Values
    weights: FloatArray
    steps: int

    @property
    def inliers(self) -> np.ndarray:
        """Indices of the candidates kept (weight above 0.5)."""
        return np.flatnonzero(self.weights > 0.5)


def gnc_tls(
    known: gtsam.NonlinearFactorGraph,
    candidates: list[FactorRecord],
    values: gtsam.Values,
    c2: float,
    params: gtsam.LevenbergMarquardtParams,
    max_steps: int = 100,
) -> GncResult:
    """Choose the inliers among ``candidates`` jointly (module docstring).

    Parameters
    ----------
    known : gtsam.NonlinearFactorGraph
        The factors taken as inliers.
    candidates : list of FactorRecord
        The factors to choose among; their ``robust`` kernel is dropped.
    values : gtsam.Values
        The start: every variable of ``known`` and ``candidates``.
    c2 : float
        The truncation ``c^2`` of a candidate's squared Mahalanobis residual (a chi-square
        quantile of its dimension).
    params : gtsam.LevenbergMarquardtParams
        Of each Levenberg-Marquardt pass.
    max_steps : int

    Returns
    -------
    GncResult
    """
    plain_records = [replace(r, robust=None) for r in candidates]
    plain = [r.to_gtsam() for r in plain_records]

    def squared(v: gtsam.Values) -> FloatArray:
        return np.array([2.0 * f.error(v) for f in plain])

    def optimise(weights: FloatArray, start: gtsam.Values) -> gtsam.Values:
        graph = gtsam.NonlinearFactorGraph(known)
        for record, w in zip(plain_records, weights, strict=True):
            if w > 1e-6:
                graph.add(replace(record, cov=record.cov / w).to_gtsam())
        return gtsam.LevenbergMarquardtOptimizer(graph, start, params).optimize()

    weights = np.ones(len(candidates))
    r2 = squared(values)
    mu = c2 / max(2.0 * float(r2.max(initial=0.0)) - c2, 1e-9)
    steps = 0
    while r2.size and r2.max() > c2 and steps < max_steps:
        lo, hi = mu / (mu + 1.0) * c2, (mu + 1.0) / mu * c2
        r = np.sqrt(np.maximum(r2, 1e-12))
        new = np.where(
            r2 <= lo,
            1.0,
            np.where(r2 >= hi, 0.0, np.sqrt(c2) / r * np.sqrt(mu * (mu + 1.0)) - mu),
        )
        new = np.clip(new, 0.0, 1.0)
        values = optimise(new, values)
        r2 = squared(values)
        settled = np.abs(new - weights).sum() < 1e-3 * max(len(new), 1)
        weights = new
        steps += 1
        if settled and np.all((weights < 1e-6) | (weights > 1.0 - 1e-6)):
            break
        mu *= 1.4
    return GncResult(optimise(weights, values), weights, steps)
