"""Uncertainty of a winning line (design.md step 7, paper 2.6), two methods.

``method="seed"``: the paper's method
-------------------------------------
For a candidate line ``(rho, theta)`` in R, the *overlap ratio* is

    (beams that have a threshold bin on the line) / (beams that would hit the line)

where a stored beam *would hit* the line when some bearing of its arc (eq. 2) meets the line at
an incidence of at most ``beta`` (eq. 3) within ``[min_range, max_range]``, and a threshold bin is
*on* the line when its arc meets the line that way (with ``+-tol`` in range). The ratio is
evaluated over a window of cells around the winner; the cells whose ratio is at least
``similarity`` times the winner's and that are connected to the winner form a region of the
``(rho, theta)`` plane. The region is approximated by its moment ellipse: centre = mean of the
cell centres, second moments ``M`` (plus the cell's own ``diag(drho^2, dtheta^2) / 12``). A uniform
ellipse ``{x : x^T E^-1 x <= 1}`` has second moments ``E / 4``, so ``E = 4 M``. The ellipse is read
as the ``confidence`` region of a Gaussian, ``x^T S^-1 x <= chi2_2(confidence)`` (5.991 at 0.95),
which gives the covariance ``S = 4 M / chi2_2(confidence)``.

``method="fit"``: a weighted least-squares fit of the voters
------------------------------------------------------------
Each voter is a bin of range ``r`` on a beam with sensor ``(x_S, y_S)`` and axis bearing ``theta_S``
in R. Its point is ``p = (x_S, y_S) + r (cos b, sin b)`` at an *effective bearing* ``b`` given by
the return model:

* ``"axis"``: ``b = theta_S`` (the echo peak on the beam axis; raw-intensity beams);
* ``"first_return"``: ``b`` = the bearing of the arc nearest to the line normal as seen from the
  sensor, ``clip(phi, theta_S - alpha/2, theta_S + alpha/2)`` (the first bin of an echo comes from the
  edge of the beam closest to perpendicular incidence; thresholded masks, where the segmentation
  keeps the nearest bin of each run).

The residual of a voter is its signed distance to the line,
``e = x cos(theta) + y sin(theta) - rho`` (with ``(x, y) = p``), with variance
``s^2 = sigma_r^2 cos^2(theta - b) + r^2 sigma_b^2 sin^2(theta - b)`` from the range noise
``sigma_r`` (default ``bin_size / sqrt(12)``) and the bearing noise across the beam ``sigma_b``
(default ``alpha / sqrt(12)``, a uniform bearing over the beam width: the dominant term).
Gauss-Newton on ``sum e^2 / s^2`` from the winning cell refines ``(rho, theta)``. The voters of one
cell are a range-truncated sample (a bin whose noisy range falls in the next rho cell does not vote
for it), so the extractor then re-gathers the fit's support around its own estimate
(:func:`support_mask`: all stored final bins within ``gate`` sigmas, from beams that see the line)
and refits. The covariance is
``P = (J^T W J)^-1``, ``J_i = [-1, -x_S sin(theta) + y_S cos(theta) - r sin(theta - b)]``. This is, to
first order, the covariance of the weighted total-least-squares line fit of Arras & Siegwart
(1997) with per-point polar covariances.

The range error of a bin is not all independent: the offset between the range of the bin that
holds an echo's peak (or first return) and the wall is common to every bin of a head (the bin
convention, the pulse's asymmetry: the vertical beam's footprint leaves a tail behind the wall),
and unlike the independent errors it does not average down with the number of voters. It is
modelled as one range offset ``c ~ N(0, sigma_c^2)`` shared by all the voters: it moves each
echo by ``c`` along its bearing, its residual by ``a_i c`` with ``a_i = cos(theta - b_i)``, hence

    P <- P + sigma_c^2 g g^T,   g = P J^T W a

(the line moves by about ``c`` in ``rho``). The extractor's default is ``sigma_c = bin_size /
sqrt(12)`` (the wall is known to be somewhere in its bin, uniformly): the peak bin of a raw echo
lies a fraction of a bin beyond the wall, which does not average down with the number of
voters. ``benchmarks/extractor_consistency.py`` measures the NEES with and without the term
(docs/simulator.md).

Optionally the pose uncertainty is added: the relative pose of each beam with respect to R is
taken as a random walk backwards from R, ``Cov(d_k, d_l) = Q(t_max(k, l))`` with
``Q(t) = psd(Sigma(t_R) - Sigma(t))`` from the :class:`~sonarslam.features.pose_source.PoseSource`
covariances (the covariance accumulated between ``t`` and ``t_R``), so that the errors of the
voters of nearby beams are correlated; it enters through the sandwich
``P + P J^T W C_pose W J P``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
from scipy import ndimage
from scipy.stats import chi2

from sonarslam.features.geometry import FloatArray, normalize_line, wrap_angle
from sonarslam.features.hough import HoughGrid
from sonarslam.features.sector import BinsInR, SectorSnapshot

__all__ = [
    "LineEstimate",
    "effective_bearings",
    "fit_line",
    "support_mask",
    "overlap_ratio",
    "seed_ellipse",
    "relative_pose_covariances",
]


@dataclass(frozen=True, eq=False)
class LineEstimate:
    """A line in R with its covariance.

    Attributes
    ----------
    rho_m, theta_rad : float
        Normalised line in R.
    cov : ndarray, shape (2, 2)
        Covariance of ``(rho_m, theta_rad)``.
    region_cells : ndarray of int64, shape (K,) or None
        Seed method: flat cells of the similar-overlap region.
    pose_term : ndarray, shape (2, 2) or None
        Fit with ``pose_cov_r``: the part of ``cov`` due to the relative pose uncertainty
        (already included in ``cov``), for a method whose covariance knows nothing of poses.
    """

    rho_m: float
    theta_rad: float
    cov: FloatArray
    region_cells: npt.NDArray[np.int64] | None = None
    pose_term: FloatArray | None = None


def _normal_seen_from(
    x_m: FloatArray, y_m: FloatArray, rho_m: npt.ArrayLike, theta_rad: npt.ArrayLike
) -> tuple[FloatArray, FloatArray]:
    """Distance from sensors to a line and the direction of the line's normal from them.

    Returns ``d >= 0`` (m) and ``phi`` (rad): the foot of the perpendicular from the sensor to
    the line is at bearing ``phi``, distance ``d``.
    """
    theta = np.asarray(theta_rad, dtype=np.float64)
    signed = np.asarray(rho_m) - x_m * np.cos(theta) - y_m * np.sin(theta)
    phi = np.where(signed >= 0.0, theta, theta + np.pi)
    return np.abs(signed), phi


def effective_bearings(
    bins: BinsInR, rho_m: float, theta_rad: float, beam_width_rad: float, return_model: str
) -> FloatArray:
    """Effective bearing in R of each bin's echo (see the module docstring).

    Parameters
    ----------
    bins : BinsInR
        N bins in R.
    rho_m, theta_rad : float
        Current line estimate in R.
    beam_width_rad : float
        ``alpha`` (rad).
    return_model : {"axis", "first_return"}

    Returns
    -------
    ndarray, shape (N,)
        Bearing (rad), within ``alpha/2`` of the beam axis, not wrapped.
    """
    if return_model == "axis":
        return bins.bearing_rad.copy()
    if return_model != "first_return":
        raise ValueError(f"unknown return model {return_model!r}")
    _, phi = _normal_seen_from(bins.x_m, bins.y_m, rho_m, theta_rad)
    off = wrap_angle(phi - bins.bearing_rad)
    half = 0.5 * beam_width_rad
    return np.asarray(bins.bearing_rad + np.clip(off, -half, half))


def _point_sigma_m(
    bins: BinsInR,
    theta_rad: float,
    bearing_rad: FloatArray,
    range_sigma_m: float,
    bearing_sigma_rad: float,
) -> FloatArray:
    """Standard deviation of each echo's distance to a line of normal ``theta`` (m)."""
    d = theta_rad - bearing_rad
    return np.asarray(
        np.sqrt(
            range_sigma_m**2 * np.cos(d) ** 2
            + bins.range_m**2 * bearing_sigma_rad**2 * np.sin(d) ** 2
        )
    )


def support_mask(
    bins: BinsInR,
    rho_m: float,
    theta_rad: float,
    *,
    beam_width_rad: float,
    incidence_beta_rad: float,
    range_sigma_m: float,
    bearing_sigma_rad: float,
    return_model: str,
    gate_sigma: float,
) -> npt.NDArray[np.bool_]:
    """Bins that support a line: echoes within ``gate_sigma`` of it, from beams that see it.

    The voters of a Hough cell are a range-truncated sample (a bin whose noisy range falls in the
    next rho cell does not vote), which biases a fit of the voters alone towards the cell; the
    fit therefore re-gathers its support around its own estimate.

    Parameters
    ----------
    bins : BinsInR
        N candidate bins in R.
    rho_m, theta_rad : float
        The line in R.
    beam_width_rad, incidence_beta_rad : float
        ``alpha`` and ``beta`` (rad).
    range_sigma_m, bearing_sigma_rad : float
        Per-bin noise (m, rad).
    return_model : {"axis", "first_return"}
    gate_sigma : float
        Gate on ``|distance| / sigma``.

    Returns
    -------
    ndarray of bool, shape (N,)
    """
    b = effective_bearings(bins, rho_m, theta_rad, beam_width_rad, return_model)
    px, py = bins.x_m + bins.range_m * np.cos(b), bins.y_m + bins.range_m * np.sin(b)
    e = px * np.cos(theta_rad) + py * np.sin(theta_rad) - rho_m
    sig = _point_sigma_m(bins, theta_rad, b, range_sigma_m, bearing_sigma_rad)
    _, phi = _normal_seen_from(bins.x_m, bins.y_m, rho_m, theta_rad)
    incidence = np.abs(wrap_angle(phi - bins.bearing_rad))
    sees = incidence <= incidence_beta_rad + 0.5 * beam_width_rad
    return np.asarray((np.abs(e) <= gate_sigma * sig) & sees)


def relative_pose_covariances(
    snapshot: SectorSnapshot, body_covariances: npt.ArrayLike, bTs: npt.ArrayLike
) -> FloatArray:
    """Covariance of each stored beam's sonar pose relative to R, expressed in R.

    ``Q_k = psd(Sigma(t_R) - Sigma(t_k))``: the body-pose covariance accumulated between the beam
    and the reference (a random walk backwards from R), mapped to the sonar pose through the
    mounting and rotated into R.

    Parameters
    ----------
    snapshot : SectorSnapshot
        B beams, oldest first; the last is R.
    body_covariances : array_like, shape (B, 3, 3)
        Covariance of the body pose ``wTb`` at each beam time (m, m, rad).
    bTs : array_like, shape (3,)
        Sonar mounting in the body frame.

    Returns
    -------
    ndarray, shape (B, 3, 3)
        ``(x_m, y_m, yaw_rad)`` covariances in R; zero for R itself.
    """
    sig = np.asarray(body_covariances, dtype=np.float64)
    diff = sig[-1][None] - sig
    diff = 0.5 * (diff + np.transpose(diff, (0, 2, 1)))
    w, v = np.linalg.eigh(diff)
    q_body = np.einsum("kij,kj,klj->kil", v, np.clip(w, 0.0, None), v)
    # sonar pose wTs = wTb * bTs: d(wTs)/d(wTb) with the lever arm (mx, my)
    m = np.asarray(bTs, dtype=np.float64)
    yaw_b = wrap_angle(snapshot.beam_wTs[:, 2] - m[2])
    c, s = np.cos(yaw_b), np.sin(yaw_b)
    g = np.zeros((sig.shape[0], 3, 3))
    g[:, 0, 0] = g[:, 1, 1] = g[:, 2, 2] = 1.0
    g[:, 0, 2] = -(s * m[0] + c * m[1])
    g[:, 1, 2] = c * m[0] - s * m[1]
    # into R: rotate the position block by -yaw(R)
    cr, sr = np.cos(snapshot.wTr[2]), np.sin(snapshot.wTr[2])
    rot = np.array([[cr, sr, 0.0], [-sr, cr, 0.0], [0.0, 0.0, 1.0]])
    gr = rot[None] @ g
    return np.asarray(gr @ q_body @ np.transpose(gr, (0, 2, 1)))


def fit_line(
    bins: BinsInR,
    rho0_m: float,
    theta0_rad: float,
    *,
    beam_width_rad: float,
    range_sigma_m: float,
    bearing_sigma_rad: float,
    return_model: str = "axis",
    n_iter: int = 5,
    pose_cov_r: npt.ArrayLike | None = None,
    range_offset_sigma_m: float = 0.0,
) -> LineEstimate:
    """Weighted least-squares line through the voters' echoes, with its covariance.

    Parameters
    ----------
    bins : BinsInR
        The N voters in R (N >= 2).
    rho0_m, theta0_rad : float
        Starting line (the winning cell).
    beam_width_rad : float
        ``alpha`` (rad).
    range_sigma_m, bearing_sigma_rad : float
        Per-bin noise in range (m) and in bearing across the beam (rad).
    return_model : {"axis", "first_return"}
        Where in the beam the echo comes from (module docstring).
    n_iter : int
        Gauss-Newton iterations.
    pose_cov_r : array_like, shape (B, 3, 3), optional
        :func:`relative_pose_covariances` of the snapshot's beams (indexed by ``bins.beam``).
    range_offset_sigma_m : float
        Standard deviation of a range error common to all the bins (m), added through
        ``P + sigma_c^2 g g^T``, ``g = P J^T W a``, ``a_i = cos(theta - b_i)`` (module docstring);
        0 leaves it out.

    Returns
    -------
    LineEstimate
    """
    rho, theta = float(rho0_m), float(theta0_rad)
    x, y, r = bins.x_m, bins.y_m, bins.range_m
    jac = np.empty((len(bins), 2))
    jac[:, 0] = -1.0
    for _ in range(max(n_iter, 1)):
        b = effective_bearings(bins, rho, theta, beam_width_rad, return_model)
        px, py = x + r * np.cos(b), y + r * np.sin(b)
        ct, st = np.cos(theta), np.sin(theta)
        e = px * ct + py * st - rho
        w = 1.0 / _point_sigma_m(bins, theta, b, range_sigma_m, bearing_sigma_rad) ** 2
        jac[:, 1] = -x * st + y * ct - r * np.sin(theta - b)
        info = jac.T @ (w[:, None] * jac)
        step = -np.linalg.solve(info, jac.T @ (w * e))
        rho_n, theta_n = normalize_line(rho + step[0], theta + step[1])
        rho, theta = float(rho_n), float(theta_n)
        if abs(step[0]) < 1e-9 and abs(step[1]) < 1e-12:
            break
    # covariance at the solution: P = (J^T W J)^-1
    b = effective_bearings(bins, rho, theta, beam_width_rad, return_model)
    d = theta - b
    w = 1.0 / _point_sigma_m(bins, theta, b, range_sigma_m, bearing_sigma_rad) ** 2
    ct, st = np.cos(theta), np.sin(theta)
    jac[:, 1] = -x * st + y * ct - r * np.sin(d)
    cov = np.linalg.inv(jac.T @ (w[:, None] * jac))
    if range_offset_sigma_m > 0.0:
        # a range offset c common to every bin moves each echo by c along its bearing, so its
        # residual by c cos(theta - b): d(rho, theta) / dc = -P J^T W a, a_i = cos(theta - b_i)
        g = cov @ (jac.T @ (w * np.cos(d)))
        cov = cov + range_offset_sigma_m**2 * np.outer(g, g)
    if pose_cov_r is not None:
        q = np.asarray(pose_cov_r, dtype=np.float64)
        # d e / d (x_S, y_S, yaw_S) of each voter
        a = np.stack([np.full_like(r, ct), np.full_like(r, st), r * np.sin(d)], axis=-1)
        later = np.maximum(bins.beam[:, None], bins.beam[None, :])  # random walk back from R
        c_pose = np.einsum("ia,ijab,jb->ij", a, q[later], a)
        k = cov @ (jac.T * w)  # (2, N)
        pose_term = k @ c_pose @ k.T
        pose_term = 0.5 * (pose_term + pose_term.T)
        cov = cov + pose_term
    else:
        pose_term = None
    cov = 0.5 * (cov + cov.T)
    return LineEstimate(rho_m=rho, theta_rad=theta, cov=cov, pose_term=pose_term)


def overlap_ratio(
    rho_m: npt.ArrayLike,
    theta_rad: npt.ArrayLike,
    snapshot: SectorSnapshot,
    *,
    beam_width_rad: float,
    incidence_beta_rad: float,
    min_range_m: float,
    max_range_m: float,
    tol_m: float,
) -> tuple[FloatArray, npt.NDArray[np.int64], npt.NDArray[np.int64]]:
    """Overlap ratio of candidate lines with the stored threshold bins (paper 2.6).

    Parameters
    ----------
    rho_m, theta_rad : array_like, shape (C,)
        Candidate lines in R.
    snapshot : SectorSnapshot
        Stored beams (B) and threshold bins (M) in R.
    beam_width_rad, incidence_beta_rad : float
        ``alpha`` and ``beta`` (rad).
    min_range_m, max_range_m : float
        Ranges the sonar sees (m).
    tol_m : float
        Range tolerance of "on the line" (m), e.g. half a bin or half a rho cell.

    Returns
    -------
    ratio : ndarray, shape (C,)
        ``n_actual / n_ideal`` (0 where ``n_ideal`` is 0).
    n_ideal : ndarray of int64, shape (C,)
        Beams whose arc would hit the line.
    n_actual : ndarray of int64, shape (C,)
        Of those, beams with at least one threshold bin on the line.
    """
    rho = np.atleast_1d(np.asarray(rho_m, dtype=np.float64))
    theta = np.atleast_1d(np.asarray(theta_rad, dtype=np.float64))
    half = 0.5 * beam_width_rad
    # per (candidate, beam): distance to the line and incidence of the beam axis
    d, phi = _normal_seen_from(
        snapshot.beam_x_m[None, :], snapshot.beam_y_m[None, :], rho[:, None], theta[:, None]
    )
    u = np.abs(wrap_angle(phi - snapshot.beam_bearing_rad[None, :]))
    u_near = np.maximum(u - half, 0.0)  # smallest incidence over the arc
    u_far = np.minimum(u + half, incidence_beta_rad)  # largest admissible incidence
    r_near = d / np.cos(u_near)
    r_far = d / np.cos(np.minimum(u_far, 0.5 * np.pi - 1e-6))
    hit = (u_near <= incidence_beta_rad) & (r_near <= max_range_m) & (r_far >= min_range_m)
    n_ideal = hit.sum(axis=1).astype(np.int64)
    thr = snapshot.threshold
    n_actual = np.zeros(rho.size, dtype=np.int64)
    if len(thr):
        # A beam counts when one of its threshold bins lies in [r_near - tol, r_far + tol]:
        # count bins in that interval with two binary searches on keys sorted by (beam, range),
        # C x B x log M work instead of a C x M mask.
        top = max_range_m + tol_m
        stride = 2.0 * top + 1.0
        keys = np.sort(thr.beam * stride + np.clip(thr.range_m, 0.0, top))
        offset = np.arange(snapshot.n_beams, dtype=np.float64)[None, :] * stride
        lo = offset + np.clip(r_near - tol_m, 0.0, top)
        hi = offset + np.clip(r_far + tol_m, 0.0, top)
        count = np.searchsorted(keys, hi.ravel(), side="right") - np.searchsorted(
            keys, lo.ravel(), side="left"
        )
        n_actual = (hit & (count.reshape(hit.shape) > 0)).sum(axis=1).astype(np.int64)
    ratio = np.where(n_ideal > 0, n_actual / np.maximum(n_ideal, 1), 0.0)
    return ratio, n_ideal, n_actual


def seed_ellipse(
    winner_cell: int,
    grid: HoughGrid,
    snapshot: SectorSnapshot,
    *,
    beam_width_rad: float,
    incidence_beta_rad: float,
    min_range_m: float,
    max_range_m: float,
    tol_m: float,
    confidence: float = 0.95,
    similarity: float = 0.8,
    window_theta_cells: int = 5,
    window_rho_cells: int = 10,
) -> LineEstimate:
    """The paper's uncertainty: the ellipse of similar-overlap cells around the winner (2.6).

    Parameters
    ----------
    winner_cell : int
        Flat cell of the winner.
    grid : HoughGrid
    snapshot : SectorSnapshot
    beam_width_rad, incidence_beta_rad, min_range_m, max_range_m, tol_m : float
        See :func:`overlap_ratio`.
    confidence : float
        Probability of the ellipse (0.95).
    similarity : float
        Cells with an overlap ratio of at least ``similarity`` times the winner's are similar.
    window_theta_cells, window_rho_cells : int
        Half sizes of the searched neighbourhood (cells).

    Returns
    -------
    LineEstimate
        Centre of the ellipse and its covariance; ``region_cells`` the similar cells.
    """
    j0, i0 = divmod(int(winner_cell), grid.n_rho)
    dj = np.arange(-window_theta_cells, window_theta_cells + 1)
    di = np.arange(-window_rho_cells, window_rho_cells + 1)
    dth, drho = grid.theta_res_rad, grid.rho_res_m
    theta_c = -np.pi + (j0 + dj + 0.5) * dth  # unwrapped around the winner
    rho_c = (i0 + di + 0.5) * drho
    tt, rr = np.meshgrid(theta_c, rho_c, indexing="ij")
    valid = rr > 0.0
    ratio = np.zeros(tt.shape)
    ratio[valid] = overlap_ratio(
        rr[valid],
        tt[valid],
        snapshot,
        beam_width_rad=beam_width_rad,
        incidence_beta_rad=incidence_beta_rad,
        min_range_m=min_range_m,
        max_range_m=max_range_m,
        tol_m=tol_m,
    )[0]
    wj, wi = window_theta_cells, window_rho_cells
    r_win = ratio[wj, wi]
    similar = valid & (ratio >= similarity * r_win) & (ratio > 0.0)
    similar[wj, wi] = True
    labels, _ = ndimage.label(similar)
    region = labels == labels[wj, wi]
    pts = np.stack([rr[region], tt[region]], axis=-1)  # (rho, theta) points of the region
    mean = pts.mean(axis=0)
    dev = pts - mean
    moments = dev.T @ dev / pts.shape[0] + np.diag([drho**2, dth**2]) / 12.0
    cov = 4.0 * moments / chi2.ppf(confidence, 2)  # ellipse E = 4 M is the confidence region
    rho_n, theta_n = normalize_line(mean[0], mean[1])
    jj, ii = np.nonzero(region)
    cells = ((j0 + dj[jj]) % grid.n_theta) * grid.n_rho + (i0 + di[ii])
    return LineEstimate(
        rho_m=float(rho_n), theta_rad=float(theta_n), cov=cov, region_cells=cells.astype(np.int64)
    )
