"""Probabilistic point-to-line ICP between two scans, with its covariance and its degeneracy.

The registration of MSISpIC (Mallios et al. 2014, after Montesano's pIC and Censi's
point-to-line ICP), on the leading edges of the sonar's echoes:

1. **Lines of the reference scan.** Each reference point with enough neighbours within
   ``normal_radius_m`` gets the local line of them: its unit normal ``n`` is the principal
   direction of least spread (a point whose neighbours form a blob gets none).
2. **Correspondences.** Each point ``p`` of the moving scan, placed by the current estimate
   ``T = (x, y, yaw)`` (``q = R(yaw) p + t``), is paired with its nearest reference point ``r``
   that has a line (scipy's ``cKDTree``), within a distance that shrinks from
   ``corr_start_m`` to ``corr_end_m``.
3. **Point-to-line residual** ``e = n . (q - r)`` with Jacobian ``J = [n_x, n_y, n . S (q - t)]``
   (``S`` the 90 deg rotation), Cauchy weights ``w = 1 / (1 + (e / (k sigma))^2)`` with
   ``sigma`` the residuals' own scale (1.4826 MAD), and a Gauss-Newton step
   ``(J^T W J) d = -J^T W e``.
4. **Degeneracy** (Zhang, Kaess, Singh 2016, "On degeneracy of optimization-based state
   estimation problems"): the information ``J^T W J`` in ``(x, y, L yaw)`` (``L`` the inliers'
   RMS radius, so that the three are in metres) is decomposed; a direction whose information is
   under ``degenerate_share`` of what the inliers would give if all of them faced it is not
   constrained: a corridor's direction along its walls. The step along it is not taken (the
   estimate keeps the guess, i.e. the odometry, there) and the measurement's variance along it
   is ``free_sigma ** 2``.
5. **Covariance**: ``cov_scale * sigma^2 (J^T W J)^-1`` at the optimum (the Hessian's, with the
   unconstrained directions replaced). For a point-to-line residual whose only noise is the
   moving points' along the normal, Censi's ``(d2J/dx2)^-1 (d2J/dzdx) Sigma_z (d2J/dzdx)^T
   (d2J/dx2)^-1`` is the same matrix at the optimum; ``cov_scale`` takes the correlation of the
   residuals of one wall (its roughness, the echo band) that neither formula knows. Checked
   against Monte Carlo on the simulator (``tests/test_scans.py``).

Convention: ``T = refTcur``, a point ``p`` of the moving scan is ``R(yaw) p + (x, y)`` in the
reference scan's frame; the covariance is in these plain ``(x_m, y_m, yaw_rad)`` coordinates.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np
import numpy.typing as npt
from scipy.spatial import cKDTree

from sonarslam.features.geometry import FloatArray, transform_points, wrap_angle
from sonarslam.features.scans.config import ScanConfig

__all__ = ["ReferenceLines", "Registration", "reference_lines", "register", "register_from"]

_S = np.array([[0.0, -1.0], [1.0, 0.0]])


@dataclass(frozen=True, eq=False)
class ReferenceLines:
    """A reference scan ready for registration: its points, a tree, the local line normals.

    Attributes
    ----------
    points : ndarray, shape (N, 2)
        Reference points with a local line (m).
    normals : ndarray, shape (N, 2)
        Unit normals of their lines.
    tree : cKDTree
        Over ``points``.
    """

    points: FloatArray
    normals: FloatArray
    tree: cKDTree


def reference_lines(points: npt.ArrayLike, config: ScanConfig) -> ReferenceLines:
    """The local line (normal) of each reference point (module docstring, step 1).

    Parameters
    ----------
    points : array_like, shape (N, 2)
        Reference scan (m).
    config : ScanConfig

    Returns
    -------
    ReferenceLines
        Only the points that have a line.
    """
    p = np.asarray(points, dtype=np.float64).reshape(-1, 2)
    if p.shape[0] < config.min_normal_points:
        empty = np.zeros((0, 2))
        return ReferenceLines(empty, empty, cKDTree(np.zeros((0, 2))))
    tree = cKDTree(p)
    groups = tree.query_ball_point(p, config.normal_radius_m)
    counts = np.array([len(g) for g in groups])
    keep = counts >= config.min_normal_points
    normals = np.zeros_like(p)
    for i in np.flatnonzero(keep):
        nb = p[groups[i]]
        d = nb - nb.mean(axis=0)
        evals, evecs = np.linalg.eigh(d.T @ d)  # ascending
        if evals[0] > config.max_normal_thickness**2 * evals[1]:
            keep[i] = False
            continue
        normals[i] = evecs[:, 0]
    pts = p[keep]
    if pts.shape[0] == 0:
        return ReferenceLines(pts, pts, cKDTree(np.zeros((0, 2))))
    return ReferenceLines(pts, normals[keep], cKDTree(pts))


@dataclass(frozen=True)
class Registration:
    """The result of :func:`register`.

    Attributes
    ----------
    z : ndarray, shape (3,)
        ``refTcur`` ``(x_m, y_m, yaw_rad)``.
    cov : ndarray, shape (3, 3)
        Its covariance in ``(x_m, y_m, yaw_rad)``, unconstrained directions at ``free_sigma``.
    guess : ndarray, shape (3,)
        The initial ``refTcur``.
    accepted : bool
        Converged with enough inliers, a small enough residual sigma and at least one
        constrained direction.
    n_points, n_inliers : int
        Points of the moving scan; those paired within ``corr_end_m`` at the end.
    sigma_m : float
        The residual sigma (m).
    constrained : ndarray, shape (3, k)
        Unit directions of ``(x_m, y_m, L yaw_rad)`` the scans constrain (columns), ``k`` of 3.
    shares : ndarray, shape (3,)
        Information share of each eigen-direction (ascending).
    length_m : float
        ``L``: the RMS distance of the inliers from the moving scan's origin (m).
    iterations : int
    reason : str
        Why it was rejected ("" if accepted).
    weight : float
        Sum of the Cauchy weights of the pairs at the end (how much of the scans agree).
    """

    z: FloatArray
    cov: FloatArray
    guess: FloatArray
    accepted: bool
    n_points: int
    n_inliers: int
    sigma_m: float
    constrained: FloatArray = field(default_factory=lambda: np.zeros((3, 0)))
    shares: FloatArray = field(default_factory=lambda: np.zeros(3))
    length_m: float = 1.0
    iterations: int = 0
    reason: str = ""
    weight: float = 0.0

    @property
    def inlier_share(self) -> float:
        return self.n_inliers / self.n_points if self.n_points else 0.0

    @property
    def n_constrained(self) -> int:
        return int(self.constrained.shape[1])


def _correspond(
    ref: ReferenceLines, q: FloatArray, max_d: float
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Index mask of paired points, their reference points and normals."""
    if ref.points.shape[0] == 0:
        return np.zeros(q.shape[0], bool), np.zeros((0, 2)), np.zeros((0, 2))
    d, idx = ref.tree.query(q, k=1, distance_upper_bound=max_d)
    ok = np.isfinite(d)
    return ok, ref.points[idx[ok]], ref.normals[idx[ok]]


def _median(a: FloatArray) -> float:
    """``np.median`` of a 1-D array without NaN, by the same partition and the same mean of the
    middle one or two (so the same value), without its generic axis and NaN handling: the
    registration asks at every iteration."""
    n = a.size
    h = n // 2
    if n % 2:
        return float(np.partition(a, h)[h])
    part = np.partition(a, [h - 1, h])
    return (float(part[h - 1]) + float(part[h])) / 2.0


def _scale(e: FloatArray, floor: float) -> float:
    """Robust residual sigma: 1.4826 times the median absolute residual, at least ``floor``."""
    if e.size == 0:
        return floor
    return max(1.4826 * _median(np.abs(e)), floor)


def _system(
    p: FloatArray, T: FloatArray, r: FloatArray, n: FloatArray, config: ScanConfig
) -> tuple[FloatArray, FloatArray, FloatArray, float, FloatArray]:
    """Residuals, Jacobians (rows), Cauchy weights, residual sigma, placed points of the pairs
    ``p -> (r, n)`` at ``T``."""
    q = transform_points(T, p)
    e = np.einsum("ij,ij->i", n, q - r)
    dq = (q - T[:2]) @ _S.T  # d q / d yaw = S R p
    J = np.column_stack([n, np.einsum("ij,ij->i", n, dq)])
    sigma = _scale(e, config.min_sigma_m)
    w = 1.0 / (1.0 + (e / (config.kernel_k * sigma)) ** 2)
    return e, J, w, sigma, q


def _radius(q: FloatArray, T: FloatArray) -> float:
    """``L``: RMS distance of the placed points from the moving scan's origin (m), at least 1."""
    return max(float(np.sqrt(np.mean(np.sum((q - T[:2]) ** 2, axis=1)))), 1.0)


def _eigen(
    H: FloatArray, L: float, n_inliers: int, sigma: float
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Eigen-decomposition of the information in ``(x, y, L yaw)``: values, vectors (columns),
    shares (values times ``sigma^2 / n_inliers``), ascending."""
    Dinv = np.diag([1.0, 1.0, 1.0 / L])
    Hs = Dinv @ H @ Dinv
    evals, evecs = np.linalg.eigh(0.5 * (Hs + Hs.T))
    shares = evals * sigma**2 / max(n_inliers, 1)
    return evals, evecs, shares


def register(
    ref: ReferenceLines, cur: npt.ArrayLike, guess: npt.ArrayLike, config: ScanConfig
) -> Registration:
    """Register the moving scan ``cur`` onto ``ref`` from ``guess`` (module docstring).

    Parameters
    ----------
    ref : ReferenceLines
        The reference scan (:func:`reference_lines`).
    cur : array_like, shape (M, 2)
        The moving scan's points in its own frame (m).
    guess : array_like, shape (3,)
        Initial ``refTcur`` ``(x_m, y_m, yaw_rad)``.
    config : ScanConfig

    Returns
    -------
    Registration
    """
    p = np.asarray(cur, dtype=np.float64).reshape(-1, 2)
    T0 = np.asarray(guess, dtype=np.float64).copy()
    T = T0.copy()
    n_it = config.iterations
    half = max(n_it // 2, 1)
    shrink = (config.corr_end_m / config.corr_start_m) ** (1.0 / half)
    sigma = config.max_sigma_m
    converged = False
    it = 0
    for it in range(1, n_it + 1):
        max_d = max(config.corr_start_m * shrink ** (it - 1), config.corr_end_m)
        ok, r, n = _correspond(ref, transform_points(T, p), max_d)
        if ok.sum() < config.min_inliers:
            break
        e, J, w, sigma, q = _system(p[ok], T, r, n, config)
        H = (J * w[:, None]).T @ J
        g = (J * w[:, None]).T @ e
        L = _radius(q, T)
        evals, V, shares = _eigen(H / sigma**2, L, int(ok.sum()), sigma)
        free = shares < config.degenerate_share
        D = np.diag([1.0, 1.0, L])
        gs = np.linalg.solve(D, g)  # the gradient in (x, y, L yaw)
        coef = np.where(free, 0.0, (V.T @ gs) / np.where(free, 1.0, evals * sigma**2))
        step = -np.linalg.solve(D, V @ coef)  # back to (x, y, yaw)
        T = np.array([T[0] + step[0], T[1] + step[1], float(wrap_angle(T[2] + step[2]))])
        small = np.hypot(step[0], step[1]) < 5e-3 and abs(step[2]) < 5e-4
        if small and max_d <= config.corr_end_m:
            converged = True
            break
    return _result(ref, p, T, T0, sigma, it, converged, config)


def _result(
    ref: ReferenceLines,
    p: FloatArray,
    T: FloatArray,
    T0: FloatArray,
    sigma: float,
    iterations: int,
    converged: bool,
    config: ScanConfig,
) -> Registration:
    """The covariance, degeneracy and acceptance at the final estimate ``T``."""
    n_pts = p.shape[0]
    free_cov = np.diag([config.free_sigma**2] * 2 + [1.0])
    ok, r, n = _correspond(ref, transform_points(T, p), config.corr_end_m)
    common = {"guess": T0, "n_points": n_pts, "iterations": iterations}
    if ok.sum() < config.min_inliers:
        return Registration(
            T,
            free_cov,
            accepted=False,
            n_inliers=int(ok.sum()),
            sigma_m=sigma,
            reason="too few pairs",
            **common,
        )
    e, J, w, sigma, q = _system(p[ok], T, r, n, config)
    inliers = int(np.sum(np.abs(e) <= config.kernel_k * sigma))
    H = (J * w[:, None]).T @ J / sigma**2
    L = _radius(q, T)
    evals, V, shares = _eigen(H, L, inliers, sigma)
    free = shares < config.degenerate_share
    info = np.where(free, 1.0 / config.free_sigma**2, evals)
    Dinv = np.diag([1.0, 1.0, 1.0 / L])
    Vc = V[:, ~free]
    floor = np.diag([config.floor_sigma_m**2] * 2 + [(L * np.deg2rad(config.floor_sigma_deg)) ** 2])
    cov_s = config.cov_scale * (V / info) @ V.T + Vc @ (Vc.T @ floor @ Vc) @ Vc.T
    cov = Dinv @ cov_s @ Dinv
    cov = 0.5 * (cov + cov.T)
    reason = ""
    if not converged:
        reason = "not converged"
    elif inliers < config.min_inliers or inliers < config.min_inlier_share * n_pts:
        reason = "too few inliers"
    elif sigma > config.max_sigma_m:
        reason = "residuals too large"
    elif free.all():
        reason = "degenerate"
    return Registration(
        z=T,
        cov=cov,
        accepted=not reason,
        n_inliers=inliers,
        sigma_m=sigma,
        constrained=V[:, ~free],
        shares=shares,
        length_m=L,
        reason=reason,
        weight=float(w.sum()),
        **common,
    )


def register_from(
    ref: ReferenceLines,
    cur: npt.ArrayLike,
    guess: npt.ArrayLike,
    guess_cov: npt.ArrayLike,
    config: ScanConfig,
) -> Registration:
    """:func:`register` from several starts around an uncertain guess; the best, or rejected as
    ambiguous.

    Starts: the guess, and the guess moved by ``starts_sigma`` sigmas either way along each of
    the two largest principal directions of ``guess_cov`` whose sigma exceeds ``corr_end_m``
    (in ``(x, y, L yaw)``, ``L`` = 10 m). The accepted result with the largest weight
    (:attr:`Registration.weight`) wins; if another accepted result lies more than ``corr_end_m``
    from it with at least ``ambiguity_ratio`` of its weight, it is rejected (``"ambiguous"``).

    Parameters
    ----------
    ref, cur, guess, config
        As :func:`register`.
    guess_cov : array_like, shape (3, 3)
        Covariance of the guess in ``(x_m, y_m, yaw_rad)``.
    """
    T0 = np.asarray(guess, dtype=np.float64)
    D = np.diag([1.0, 1.0, 10.0])
    evals, evecs = np.linalg.eigh(D @ np.asarray(guess_cov, dtype=np.float64) @ D)
    starts = [T0]
    for i in (2, 1):
        sd = float(np.sqrt(max(evals[i], 0.0)))
        if sd > config.corr_end_m:
            for sign in (1.0, -1.0):
                starts.append(
                    T0 + np.linalg.solve(D, sign * config.starts_sigma * sd * evecs[:, i])
                )
    results = [register(ref, cur, T, config) for T in starts]
    ok = [r for r in results if r.accepted]
    if not ok:
        return results[0]
    best = max(ok, key=lambda r: r.weight)
    for r in ok:
        far = np.hypot(*(r.z[:2] - best.z[:2])) > config.corr_end_m
        if far and r.weight >= config.ambiguity_ratio * best.weight:
            return replace(best, accepted=False, reason="ambiguous", guess=T0)
    return replace(best, guess=T0)
