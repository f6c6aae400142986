"""Line features against the simulator's true walls: matching, errors and NEES.

A feature ``(rho, theta)`` with covariance ``P`` lives in its frame R (pose ``wTr``). A true wall
is a world segment; its infinite line, expressed in R with
:func:`sonarslam.features.geometry.line_world_to_frame`, is the truth of any feature lying on it.

* Matching (:func:`match_features`): each feature goes to the true wall whose infinite line is
  nearest to the feature's segment, the distance being the larger of the distances of the two
  world endpoints to the line (m); this is sign-free (it does not depend on the normal's
  direction) and treats collinear walls as the same line, as a line feature must. A feature is
  *matched* when that distance is at most ``gate_m`` and the angle between the lines at most
  ``gate_rad``; otherwise it is *false*.
* Error (:func:`line_error_r`): ``e = (rho - rho_true, wrap(theta - theta_true))`` in R, taken
  sign-free (:func:`sonarslam.features.geometry.line_difference`).
* NEES ``e^T P^-1 e`` (:func:`sonarslam.slam.eval.consistency.nees`): for a consistent estimator a chi2
  variable with 2 degrees of freedom; the mean of ``N`` independent ones lies in
  :func:`sonarslam.slam.eval.consistency.mean_nees_band` with probability 0.95.

The trials that simulate a run and extract its lines with the true poses are
:mod:`sonarslam.slam.run.line_trials`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from sonarslam.features.geometry import FloatArray, line_difference, line_world_to_frame
from sonarslam.features.line import LineFeature
from sonarslam.slam.eval.consistency import nees
from sonarslam.slam.eval.truth import wall_lines_world

__all__ = [
    "Match",
    "line_error_r",
    "match_features",
    "POOL_GATE_M",
    "HARBOUR_GATE_M",
    "GATE_RAD",
]

#: Largest endpoint distance (m) and angle (rad) of a matched feature: pool (1.2 cm bins, walls
#: 0.8-2.5 m away) and harbour (10 cm bins, walls up to 50 m away).
POOL_GATE_M = 0.1
HARBOUR_GATE_M = 1.0
GATE_RAD = float(np.deg2rad(5.0))


@dataclass(frozen=True)
class Match:
    """A feature against its nearest true wall.

    Attributes
    ----------
    wall : int
        Index of the nearest wall (by line).
    distance_m : float
        Larger distance of the feature's world endpoints to that wall's line (m).
    error : ndarray, shape (2,)
        ``(rho_m, theta_rad)`` error in R, sign-free (:func:`line_error_r`).
    nees : float
        ``error^T cov^-1 error``.
    matched : bool
        Inside the gates of :func:`match_features`.
    """

    wall: int
    distance_m: float
    error: FloatArray
    nees: float
    matched: bool


def line_error_r(feature: LineFeature, line_w: npt.ArrayLike) -> FloatArray:
    """Sign-free error of a feature against a world line, in the feature's frame R.

    Parameters
    ----------
    feature : LineFeature
    line_w : array_like, shape (2,)
        True world line ``(rho_m, theta_rad)``.

    Returns
    -------
    ndarray, shape (2,)
        ``(rho_m, theta_rad)`` error.
    """
    return line_difference(feature.z, line_world_to_frame(line_w, feature.wTr)[0])[0]


def match_features(
    features: list[LineFeature],
    walls_m: npt.ArrayLike,
    gate_m: float,
    gate_rad: float,
) -> list[Match]:
    """Each feature against the nearest true wall line (module docstring).

    Parameters
    ----------
    features : list of LineFeature
        With world poses ``wTr`` in the frame of ``walls_m``.
    walls_m : array_like, shape (S, 2, 2)
        True wall segments (world, m).
    gate_m : float
        Largest endpoint distance of a matched feature (m).
    gate_rad : float
        Largest angle between a matched feature and its wall (rad).

    Returns
    -------
    list of Match
        One per feature, in order.
    """
    lines_w = wall_lines_world(walls_m)
    normals = np.stack([np.cos(lines_w[:, 1]), np.sin(lines_w[:, 1])], axis=-1)  # (S, 2)
    out: list[Match] = []
    for ft in features:
        ends = ft.endpoints_world()  # (2, 2)
        dist = np.abs(ends @ normals.T - lines_w[None, :, 0]).max(axis=0)  # (S,)
        k = int(np.argmin(dist))
        e = line_error_r(ft, lines_w[k])
        ok = bool(dist[k] <= gate_m and abs(e[1]) <= gate_rad)
        out.append(Match(k, float(dist[k]), e, float(nees(e[None], ft.cov[None])[0]), ok))
    return out
