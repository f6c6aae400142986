"""Variance components: how much larger a group of factors' covariances must be for the graph's
residuals to be what their covariances say, estimated from the residuals at the optimum.

For a factor ``i`` with whitened Jacobian ``A_i`` (its rows ``R_i^{-1/2} J_i``) and whitened
residual ``b_i`` at the optimum, its *redundancy* is ``r_i = d_i - tr(A_i Sigma_i A_i^T)``
(``d_i`` its dimension, ``Sigma_i`` the joint marginal covariance of its variables): the share
of its own measurement the rest of the graph checks. With every factor of a group ``g`` of
covariance ``s_g R_i``, ``E[sum_i |b_i|^2] = sum_i r_i`` at the true ``s_g``, hence the estimate
``s_g = sum_i |b_i|^2 / sum_i r_i`` of the group's scale relative to the covariances it was
evaluated with (Förstner 1979, "Ein Verfahren zur Schätzung von Varianz- und
Kovarianzkomponenten"; Koch 1999, "Parameter Estimation and Hypothesis Testing in Linear
Models", sec. 3.6.3). Iterated, each scale applied and the graph re-optimised, it converges to
the maximum-likelihood scales (Koch's iterated estimate).

Robust kernels are left out (the residuals are the Gaussian ones): the group should be the
consistent set (the inliers a joint decision kept).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace

import gtsam
import numpy as np

from sonarslam.slam.backends.isam2.graph_io import FactorRecord

__all__ = ["VarianceComponent", "variance_component"]


@dataclass(frozen=True)
class VarianceComponent:
    """The estimate of one group's covariance scale.

    Attributes
    ----------
    scale : float
        ``sum |b|^2 / sum r``: the factor by which the group's covariances (as evaluated) are
        too small (above 1) or too large (below 1); NaN when the group has no redundancy.
    squared : float
        ``sum_i |b_i|^2``.
    redundancy : float
        ``sum_i r_i``.
    n : int
        Factors in the group.
    """

    scale: float
    squared: float
    redundancy: float
    n: int


def variance_component(
    records: Sequence[FactorRecord], values: gtsam.Values, marginals: gtsam.Marginals
) -> VarianceComponent:
    """The covariance scale of the group ``records`` at the optimum ``values`` (module
    docstring).

    Parameters
    ----------
    records : sequence of FactorRecord
        The group; each a factor of the graph ``marginals`` was computed on.
    values : gtsam.Values
        The optimum.
    marginals : gtsam.Marginals
        Of the whole graph at ``values``.

    Returns
    -------
    VarianceComponent
    """
    squared = 0.0
    redundancy = 0.0
    for record in records:
        factor = replace(record, robust=None).to_gtsam()
        linear = factor.linearize(values)
        A, b = linear.jacobian()  # whitened: the factor's noise is folded in
        keys = list(linear.keys())
        joint = marginals.jointMarginalCovariance(keys)
        blocks = [[np.asarray(joint.at(ki, kj)) for kj in keys] for ki in keys]
        Sigma = np.block(blocks)
        squared += float(b @ b)
        redundancy += float(A.shape[0] - np.trace(A @ Sigma @ A.T))
    scale = squared / redundancy if redundancy > 1e-9 else float("nan")
    return VarianceComponent(scale, squared, redundancy, len(records))
