"""Data association of line observations to line landmarks, for any back end.

The back end describes its belief as a joint Gaussian over a vector ``s`` (the EKF: its whole
state; the factor graph: the current pose and the candidate landmarks, from iSAM2 marginals):
landmark ``j`` predicts the observation ``z_hat[j]`` with Jacobian ``H[j] = d z_hat[j] / d s``.
Observation ``i`` is ``z[i]`` with covariance ``R[i]``; all lines are ``(rho_m, theta_rad)``.

* individual compatibility: squared Mahalanobis distance of each pairing, gated by chi2(2);
* nearest neighbour: greedy on that distance, each landmark used once;
* JCBB (Neira & Tardos 2001): the largest set of pairings that is *jointly* compatible
  (chi2 with 2n dof on the stacked innovation), ties broken by the smaller joint distance.

Near ``rho = 0`` a line has two close representations, ``(rho, theta)`` and
``(-rho, theta + pi)``; :func:`sonarslam.features.geometry.line_difference` compares in the one that is
nearest.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.stats import chi2

from sonarslam.features.geometry import FLIP_RHO, FloatArray, along_line, line_difference
from sonarslam.settings import bounded, check_fields, one_of

__all__ = [
    "AssociationConfig",
    "AssociationProblem",
    "individual_compatibility",
    "nearest_neighbour",
    "jcbb",
    "associate",
    "extent_allowed",
]


@dataclass(frozen=True)
class AssociationConfig:
    """How observations are paired with landmarks.

    Attributes
    ----------
    method : str
        ``"jcbb"`` (default) or ``"nn"``.
    gate_probability : float
        Probability of the chi2 gates (individual: 2 dof; joint: 2n dof).
    """

    method: str = one_of("jcbb", "jcbb", "nn")
    gate_probability: float = bounded(0.99, 0.0, 1.0, low_open=True, high_open=True)

    def __post_init__(self) -> None:
        check_fields(self)


@dataclass(frozen=True)
class AssociationProblem:
    """Observations, predictions and the joint covariance they depend on.

    Attributes
    ----------
    z : ndarray, shape (m, 2)
    R : ndarray, shape (m, 2, 2)
    z_hat : ndarray, shape (k, 2)
    H : ndarray, shape (k, 2, d)
    P : ndarray, shape (d, d)
    allowed : ndarray of bool, shape (m, k), optional
        Pairings the back end rules out on other grounds (the landmark's extent, the side of
        the line it was seen from) are False: they are never made, whatever their distance.
    """

    z: FloatArray
    R: FloatArray
    z_hat: FloatArray
    H: FloatArray
    P: FloatArray
    allowed: np.ndarray | None = None


def _pair_terms(problem: AssociationProblem) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Innovations (m, k, 2), observation covariances as compared (m, k, 2, 2), and H P H^T."""
    m, k = problem.z.shape[0], problem.z_hat.shape[0]
    nu = np.zeros((m, k, 2))
    R = np.zeros((m, k, 2, 2))
    for i in range(m):
        for j in range(k):
            nu[i, j], flipped = line_difference(problem.z[i], problem.z_hat[j])
            R[i, j] = FLIP_RHO @ problem.R[i] @ FLIP_RHO if flipped else problem.R[i]
    return nu, R, problem.H


def individual_compatibility(
    problem: AssociationProblem,
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Squared Mahalanobis distance of every pairing.

    Returns
    -------
    d2 : ndarray, shape (m, k)
        Infinite for the pairings ``problem.allowed`` rules out.
    nu : ndarray, shape (m, k, 2)
    R_pair : ndarray, shape (m, k, 2, 2)
    """
    nu, R_pair, H = _pair_terms(problem)
    HPHt = np.einsum("kad,de,kbe->kab", H, problem.P, H) if H.size else np.zeros((0, 2, 2))
    S = HPHt[None, :, :, :] + R_pair
    d2 = (
        np.einsum("mka,mkab,mkb->mk", nu, np.linalg.inv(S), nu)
        if nu.size
        else np.zeros(nu.shape[:2])
    )
    if problem.allowed is not None:
        d2 = np.where(problem.allowed, d2, np.inf)
    return d2, nu, R_pair


def nearest_neighbour(problem: AssociationProblem, config: AssociationConfig) -> list[int | None]:
    """Greedy nearest neighbour under the individual gate; each landmark at most once."""
    m, k = problem.z.shape[0], problem.z_hat.shape[0]
    out: list[int | None] = [None] * m
    if m == 0 or k == 0:
        return out
    d2, _, _ = individual_compatibility(problem)
    gate = chi2.ppf(config.gate_probability, 2)
    used: set[int] = set()
    for flat in np.argsort(d2, axis=None):
        i, j = divmod(int(flat), k)
        if d2[i, j] > gate:
            break
        if out[i] is None and j not in used:
            out[i] = j
            used.add(j)
    return out


def jcbb(problem: AssociationProblem, config: AssociationConfig) -> list[int | None]:
    """Joint compatibility branch and bound (Neira & Tardos 2001)."""
    m, k = problem.z.shape[0], problem.z_hat.shape[0]
    if m == 0 or k == 0:
        return [None] * m
    d2, nu, R_pair = individual_compatibility(problem)
    gate1 = chi2.ppf(config.gate_probability, 2)
    candidates = [[j for j in np.argsort(d2[i]) if d2[i, j] <= gate1] for i in range(m)]
    gates = {n: chi2.ppf(config.gate_probability, 2 * n) for n in range(1, m + 1)}
    best: list[int | None] = [None] * m
    best_score = (0, 0.0)  # (pairings, -joint distance)

    def joint_d2(pairs: list[tuple[int, int]]) -> float:
        idx_i = [i for i, _ in pairs]
        idx_j = [j for _, j in pairs]
        v = nu[idx_i, idx_j].reshape(-1)
        Hs = problem.H[idx_j].reshape(-1, problem.P.shape[0])
        S = Hs @ problem.P @ Hs.T
        for n, (i, j) in enumerate(pairs):
            S[2 * n : 2 * n + 2, 2 * n : 2 * n + 2] += R_pair[i, j]
        return float(v @ np.linalg.solve(S, v))

    def search(i: int, pairs: list[tuple[int, int]], used: set[int], dist: float) -> None:
        nonlocal best, best_score
        if i == m:
            score = (len(pairs), -dist)
            if score > best_score:
                best_score = score
                best = [None] * m
                for a, b in pairs:
                    best[a] = b
            return
        if len(pairs) + (m - i) < best_score[0]:
            return  # bound: cannot beat the best even if every remaining one pairs
        for j in candidates[i]:
            if j in used:
                continue
            trial = [*pairs, (i, int(j))]
            d = joint_d2(trial)
            if d <= gates[len(trial)]:
                search(i + 1, trial, used | {int(j)}, d)
        if len(pairs) + (m - i - 1) >= best_score[0]:
            search(i + 1, pairs, used, dist)  # observation i is new or spurious

    search(0, [], set(), 0.0)
    return best


def associate(problem: AssociationProblem, config: AssociationConfig) -> list[int | None]:
    """Landmark index (or None) for each observation, by ``config.method``."""
    if config.method == "nn":
        return nearest_neighbour(problem, config)
    return jcbb(problem, config)


def extent_allowed(
    lines_w: FloatArray,
    extents_m: FloatArray,
    segments_w: FloatArray,
    margin_m: float | None,
    max_extent_m: float | None = None,
) -> np.ndarray:
    """Which (observation, landmark) pairings overlap along the line, within a margin.

    A line landmark is an infinite line, but the wall it stands for is a segment: an
    observation of another stretch of a long, not quite straight wall (or of a collinear quay
    far away) would pull the pose by the wall's bend. This gate keeps an observation to the
    landmarks whose extent its own segment reaches, give or take ``margin_m``.

    Parameters
    ----------
    lines_w : ndarray, shape (k, 2)
        Landmark lines ``(rho_m, theta_rad)`` (world).
    extents_m : ndarray, shape (k, 2)
        Their extents ``(s_min, s_max)`` along the line (:func:`sonarslam.features.geometry.along_line`).
    segments_w : ndarray, shape (m, 2, 2)
        Each observation's two end points in the world (m).
    margin_m : float or None
        How far beyond a landmark's extent an observation may start (m); None: any distance.
    max_extent_m : float or None
        The longest a landmark's extent may grow (m): a pairing is allowed only when the extent
        grown by the observed segment is at most this long (or no longer than the longer of
        the two alone). None: no limit.

    Returns
    -------
    ndarray of bool, shape (m, k)
    """
    m, k = len(segments_w), len(lines_w)
    out = np.zeros((m, k), dtype=bool)
    for j in range(k):
        s = along_line(lines_w[j], np.asarray(segments_w, dtype=np.float64).reshape(-1, 2))
        s = s.reshape(m, 2)
        lo, hi = s.min(axis=1), s.max(axis=1)
        ok = np.ones(m, dtype=bool)
        if margin_m is not None:
            ok &= (hi >= extents_m[j, 0] - margin_m) & (lo <= extents_m[j, 1] + margin_m)
        if max_extent_m is not None:
            grown = np.maximum(hi, extents_m[j, 1]) - np.minimum(lo, extents_m[j, 0])
            alone = np.maximum(hi - lo, extents_m[j, 1] - extents_m[j, 0])
            ok &= grown <= np.maximum(max_extent_m, alone)
        out[:, j] = ok
    return out
