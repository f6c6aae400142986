"""Two landmarks of one wall: the joint-compatibility test that finds them.

Two active landmarks are of the same wall when they were seen from the same side, their extents
overlap or lie within ``extent_margin_m`` of each other along the line, and their lines are
jointly compatible: ``d2 = nu^T S^-1 nu <= gate`` with ``nu`` their sign-free difference
(:func:`sonarslam.features.geometry.line_difference`) and ``S`` its covariance from the back end's joint
covariance of the two lines (the joint-compatibility test of Neira & Tardos 2001, on the pair).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from sonarslam.features.geometry import FLIP_RHO, FloatArray, along_line, line_difference

if TYPE_CHECKING:  # the landmark layer imports this module: its types only, for the checker
    from sonarslam.slam.mapping.landmarks import Landmark, LandmarkMap
    from sonarslam.slam.mapping.vote import LandmarkBelief

__all__ = ["duplicate_of", "extent_gap_m"]


def extent_gap_m(a: Landmark, line_a: FloatArray, b: Landmark, line_b: FloatArray) -> float:
    """The gap (m, negative when they overlap) between two landmarks' extents along ``a``'s
    line, ``b``'s projected onto it."""
    s_b = along_line(line_a, b.ends_w(line_b))
    lo_a, hi_a = a.extent_on(line_a)
    return float(max(lo_a, s_b.min()) - min(hi_a, s_b.max()))


def duplicate_of(
    landmarks: LandmarkMap, belief: LandmarkBelief, landmark_id: int, gate: float
) -> Landmark | None:
    """The first other active landmark of the same wall as ``landmark_id`` (module docstring),
    or None.

    Parameters
    ----------
    landmarks : LandmarkMap
    belief : LandmarkBelief
        The back end's lines and their joint covariance (``cov``, over ``cov_ids``); landmarks
        it has no line of (promoted in this vote) are not compared.
    landmark_id : int
    gate : float
        chi2(2) threshold of the test.
    """
    assert belief.cov is not None, "the merge test needs the lines' joint covariance"
    lm_j = landmarks.landmarks[landmark_id]
    line_j = belief.lines_w[landmark_id]
    margin = landmarks.config.extent_margin_m or 0.0
    at = {j: 2 * c for c, j in enumerate(belief.cov_ids)}
    for lm_i in landmarks.active():
        if lm_i.id == landmark_id or lm_i.side != lm_j.side or lm_i.id not in belief.lines_w:
            continue
        line_i = belief.lines_w[lm_i.id]
        if extent_gap_m(lm_i, line_i, lm_j, line_j) > margin:
            continue
        nu, flipped = line_difference(line_j, line_i)
        A = np.hstack([-np.eye(2), FLIP_RHO if flipped else np.eye(2)])
        idx = np.r_[at[lm_i.id] : at[lm_i.id] + 2, at[landmark_id] : at[landmark_id] + 2]
        S = A @ belief.cov[np.ix_(idx, idx)] @ A.T
        if nu @ np.linalg.solve(S, nu) <= gate:
            return lm_i
    return None
