"""The (theta, rho) voting space in frame R, voting with the sonar model, and winners.

Design.md steps 4-6, paper 2.4-2.5.

The voting space
----------------
A grid of line normals ``theta`` in ``[-pi, pi)`` (``n_theta`` cells, always even so that
``theta + pi`` is a cell too) by line distances ``rho`` in ``[0, range_max]`` (``n_rho`` cells).
Cell ``(j, i)`` holds ``theta`` in ``[-pi + j dtheta, -pi + (j + 1) dtheta)`` and ``rho`` in
``[i drho, (i + 1) drho)``; its flat index is ``j * n_rho + i`` and its centre
``(theta_j, rho_i) = (-pi + (j + 1/2) dtheta, (i + 1/2) drho)``.

The sonar model (paper eqs. 2-4)
--------------------------------
A bin of range ``rho_S`` of a beam whose sensor sits at ``(x_S, y_S)`` in R with beam-axis bearing
``theta_S`` is not a point but an arc of the horizontal beam width ``alpha``:

* eq. 2: the arc is sampled at ``h`` bearings ``theta_h`` in ``[theta_S - alpha/2, theta_S + alpha/2]``;
* eq. 3: a surface seen at an incidence up to ``beta`` still returns an echo, so the arc point at
  ``theta_h`` may lie on any line whose normal is ``theta_{h,p}`` in ``[theta_h - beta, theta_h + beta]``
  (``p`` samples);
* eq. 4: that line's distance. The arc point at ``theta_h`` is
  ``(x_S + rho_S cos theta_h, y_S + rho_S sin theta_h)``, so the line of normal ``theta_{h,p}`` through it is::

      rho_{h,p} = x_S cos theta_{h,p} + y_S sin theta_{h,p} + rho_S cos(theta_{h,p} - theta_h)

  The paper prints ``cos(theta_{h,p} - theta_S)`` in the last term: that is the same formula with
  the arc point taken on the beam axis for every ``h``, exact only for ``h = 1``; it puts the
  lines up to ``rho_S (1 - cos(alpha/2)) + rho_S sin(beta) alpha/2`` (1.2 m at 50 m) off the arc.
  This module implements the geometric form above (:func:`eq4_rho`).

A negative ``rho_{h,p}`` is the line ``(-rho, theta + pi)`` (:func:`sonarslam.features.geometry.normalize_line`).
A bin gives at most one vote to a cell.

Two ways to cast the votes (both vectorised over all bins, no Python loop per bin or vote):

* ``"samples"`` (:func:`vote_samples`): eqs. 2-4 literally: all ``(bin, h, p)`` samples, their cells,
  one vote per distinct ``(bin, cell)`` pair (``np.unique`` of ``bin * n_cells + cell``).
* ``"arc"`` (:func:`vote_arc`, the default; :func:`vote_arc_compiled` is the same computation
  compiled, which the extractor uses): the limit ``h, p -> infinity`` of eqs. 2-3. For each bin
  and each theta cell that meets the span of normals ``[theta_S - alpha/2 - beta, theta_S + alpha/2 + beta]``,
  the interval of ``rho`` swept by eq. 4 over the normals of the cell and the part of the arc that
  eq. 3 allows for them (``|theta - theta_h| <= beta``) is computed in closed form (at the ends and the
  middle of the cell's normals; ``cos`` is monotone away from 0), and every rho cell it meets gets
  one vote. The ``(bin, cell)`` pairs are distinct by construction, so no deduplication is needed;
  no gaps open in rho at long range (as a fixed ``h`` does); and its work grows with the cells a
  bin meets, not with ``h * p`` samples.
  Its votes are those of ``"samples"`` with dense ``h`` and ``p`` (checked in ``tests/test_hough.py``).

Compiled kernel
---------------
A vote has tens to a few thousand bins and ~30 theta cells per bin: in numpy its time is the
overhead of some forty array calls, not arithmetic. :func:`vote_arc_compiled` runs the same
floating-point operations in the same order in one loop compiled by numba (its ``cos`` and
``sin`` are the C library's, as numpy's), so its votes are identical, element by element and in
order, to :func:`vote_arc`'s (checked in ``tests/test_hough.py``, which keeps :func:`vote_arc`
as the reference). It is compiled at its first call and cached beside the module.

Winners (paper 2.5)
-------------------
The cell with most votes wins if it has at least ``min_votes``; its voters are removed (with the
bins that voted within a small suppression window around it, so that one wall gives one line),
the accumulator is decremented by all their votes, and the search repeats.
"""

from __future__ import annotations

from dataclasses import dataclass

import numba
import numpy as np
import numpy.typing as npt

from sonarslam.features.geometry import FloatArray, normalize_line

__all__ = [
    "HoughGrid",
    "Votes",
    "Winner",
    "eq4_rho",
    "sonar_model_samples",
    "vote_samples",
    "vote_arc",
    "vote_arc_compiled",
    "accumulate",
    "find_winners",
    "find_winners_reference",
    "auto_h_bearings",
    "auto_p_angles",
]

IntArray = npt.NDArray[np.int64]


@dataclass(frozen=True)
class HoughGrid:
    """The ``(theta, rho)`` voting space in frame R (paper 2.4).

    Attributes
    ----------
    n_theta : int
        Cells in ``theta`` over ``[-pi, pi)``; even.
    n_rho : int
        Cells in ``rho`` over ``[0, n_rho * rho_res_m)``.
    rho_res_m : float
        Cell size in ``rho`` (m).
    """

    n_theta: int
    n_rho: int
    rho_res_m: float

    def __post_init__(self) -> None:
        if self.n_theta < 2 or self.n_theta % 2:
            raise ValueError(f"HoughGrid.n_theta must be even and >= 2, got {self.n_theta}")
        if self.n_rho < 1 or self.rho_res_m <= 0.0:
            raise ValueError("HoughGrid needs n_rho >= 1 and rho_res_m > 0")

    @classmethod
    def from_resolution(
        cls, theta_res_rad: float, rho_res_m: float, range_max_m: float
    ) -> HoughGrid:
        """Grid with about ``theta_res_rad`` (rounded so that ``2 pi`` holds an even number of
        cells) and ``rho_res_m`` (exact) covering ``rho`` in ``[0, range_max_m]``."""
        if theta_res_rad <= 0.0:
            raise ValueError(f"theta_res_rad must be positive, got {theta_res_rad}")
        n_theta = 2 * max(int(round(np.pi / theta_res_rad)), 1)
        n_rho = max(int(np.ceil(range_max_m / rho_res_m - 1e-9)), 1)
        return cls(n_theta=n_theta, n_rho=n_rho, rho_res_m=float(rho_res_m))

    @property
    def theta_res_rad(self) -> float:
        """Cell size in ``theta`` (rad)."""
        return 2.0 * np.pi / self.n_theta

    @property
    def n_cells(self) -> int:
        return self.n_theta * self.n_rho

    @property
    def shape(self) -> tuple[int, int]:
        return (self.n_theta, self.n_rho)

    def theta_centers_rad(self) -> FloatArray:
        """Cell centres in ``theta``, shape (n_theta,) (rad)."""
        return np.asarray(-np.pi + (np.arange(self.n_theta) + 0.5) * self.theta_res_rad)

    def rho_centers_m(self) -> FloatArray:
        """Cell centres in ``rho``, shape (n_rho,) (m)."""
        return np.asarray((np.arange(self.n_rho) + 0.5) * self.rho_res_m, dtype=np.float64)

    def cell_center(self, cell: npt.ArrayLike) -> tuple[FloatArray, FloatArray]:
        """``(rho_m, theta_rad)`` of the centres of flat cells."""
        c = np.asarray(cell, dtype=np.int64)
        j, i = np.divmod(c, self.n_rho)
        return (i + 0.5) * self.rho_res_m, -np.pi + (j + 0.5) * self.theta_res_rad

    def cell_of(self, rho_m: npt.ArrayLike, theta_rad: npt.ArrayLike) -> IntArray:
        """Flat cell of lines (normalised first); -1 where ``rho`` is beyond the grid."""
        rho, theta = normalize_line(rho_m, theta_rad)
        j = np.floor((theta + np.pi) / self.theta_res_rad).astype(np.int64) % self.n_theta
        i = np.floor(rho / self.rho_res_m).astype(np.int64)
        return np.where(i < self.n_rho, j * self.n_rho + i, -1)


@dataclass(frozen=True, eq=False)
class Votes:
    """One vote per distinct ``(bin, cell)`` pair.

    Attributes
    ----------
    bin_index : ndarray of int64, shape (V,)
        Voting bin (index into the bins given to the voting function).
    cell : ndarray of int64, shape (V,)
        Flat cell of :class:`HoughGrid`.
    n_bins : int
        Number of bins that were given.
    """

    bin_index: IntArray
    cell: IntArray
    n_bins: int


@dataclass(frozen=True, eq=False)
class Winner:
    """A winning cell (a line) of one vote.

    Attributes
    ----------
    cell : int
        Flat cell index.
    rho_m, theta_rad : float
        Centre of the cell: the line in R.
    votes : int
        Votes of the cell when it won.
    voters : ndarray of int64, shape (votes,)
        Bins that voted for the cell (indices into the bins given to the voting function).
    removed : ndarray of int64, shape (R,)
        All bins removed with this winner: the voters and the bins that voted within the
        suppression window; a superset of ``voters``.
    """

    cell: int
    rho_m: float
    theta_rad: float
    votes: int
    voters: IntArray
    removed: IntArray


def eq4_rho(
    x_m: npt.ArrayLike,
    y_m: npt.ArrayLike,
    theta_line_rad: npt.ArrayLike,
    range_m: npt.ArrayLike,
    theta_h_rad: npt.ArrayLike,
) -> FloatArray:
    """Eq. 4 (geometric form): distance of the line of normal ``theta_line`` through the arc point.

    ``rho = x_S cos(theta) + y_S sin(theta) + rho_S cos(theta - theta_h)``; see the module
    docstring for the relation to the printed eq. 4 (which has ``theta_S`` for ``theta_h``).

    Parameters
    ----------
    x_m, y_m : array_like
        Sensor position in R (m).
    theta_line_rad : array_like
        Line normal ``theta_{h,p}`` (rad).
    range_m : array_like
        Bin range ``rho_S`` (m).
    theta_h_rad : array_like
        Bearing of the arc point ``theta_h`` (rad).

    Returns
    -------
    ndarray
        ``rho`` (m), not normalised (may be negative); broadcast shape of the inputs.
    """
    th = np.asarray(theta_line_rad, dtype=np.float64)
    return np.asarray(
        np.asarray(x_m) * np.cos(th)
        + np.asarray(y_m) * np.sin(th)
        + np.asarray(range_m) * np.cos(th - np.asarray(theta_h_rad))
    )


def auto_p_angles(incidence_beta_rad: float, theta_res_rad: float) -> int:
    """Eq. 3 samples so that consecutive line angles are at most one theta cell apart."""
    return int(np.ceil(2.0 * incidence_beta_rad / theta_res_rad - 1e-9)) + 1


def auto_h_bearings(
    beam_width_rad: float, incidence_beta_rad: float, rho_res_m: float, range_max_m: float
) -> int:
    """Eq. 2 samples so that, at the maximum range and incidence, consecutive arc points move a
    line's ``rho`` by at most one rho cell (``range * sin(beta) * dtheta_h <= drho``)."""
    spread_m = range_max_m * np.sin(incidence_beta_rad) * beam_width_rad
    return int(np.ceil(spread_m / rho_res_m - 1e-9)) + 1


def sonar_model_samples(
    x_m: FloatArray,
    y_m: FloatArray,
    bearing_rad: FloatArray,
    range_m: FloatArray,
    beam_width_rad: float,
    incidence_beta_rad: float,
    h_bearings: int,
    p_angles: int,
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """The ``(bin, h, p)`` samples of eqs. 2-4.

    Parameters
    ----------
    x_m, y_m, bearing_rad, range_m : ndarray, shape (N,)
        Per bin: sensor position in R (m), beam-axis bearing ``theta_S`` in R (rad), range (m).
    beam_width_rad : float
        Horizontal beam width ``alpha`` (rad).
    incidence_beta_rad : float
        Maximum incidence ``beta`` (rad).
    h_bearings, p_angles : int
        Samples of eq. 2 and eq. 3 (1 gives the centre value only).

    Returns
    -------
    rho_m : ndarray, shape (N, h, p)
        Eq. 4, not normalised (m).
    theta_rad : ndarray, shape (N, h, p)
        Line normals ``theta_{h,p}``, not wrapped (rad).
    theta_h_rad : ndarray, shape (N, h, 1)
        Arc bearings ``theta_h`` (rad).
    """
    half_a = 0.5 * beam_width_rad if h_bearings > 1 else 0.0
    half_b = incidence_beta_rad if p_angles > 1 else 0.0
    dh = np.linspace(-half_a, half_a, h_bearings)
    dp = np.linspace(-half_b, half_b, p_angles)
    theta_h = bearing_rad[:, None, None] + dh[None, :, None]  # eq. 2
    theta_hp = theta_h + dp[None, None, :]  # eq. 3
    rho = eq4_rho(
        x_m[:, None, None], y_m[:, None, None], theta_hp, range_m[:, None, None], theta_h
    )  # eq. 4 (geometric form)
    return rho, theta_hp, theta_h


def vote_samples(
    x_m: FloatArray,
    y_m: FloatArray,
    bearing_rad: FloatArray,
    range_m: FloatArray,
    grid: HoughGrid,
    beam_width_rad: float,
    incidence_beta_rad: float,
    h_bearings: int,
    p_angles: int,
) -> Votes:
    """Votes of eqs. 2-4 sampled literally, one per distinct ``(bin, cell)``.

    Parameters are those of :func:`sonar_model_samples` plus the ``grid``.
    """
    n = int(range_m.shape[0])
    rho, theta, _ = sonar_model_samples(
        x_m, y_m, bearing_rad, range_m, beam_width_rad, incidence_beta_rad, h_bearings, p_angles
    )
    cell = grid.cell_of(rho, theta).reshape(n, -1)
    bins = np.broadcast_to(np.arange(n, dtype=np.int64)[:, None], cell.shape)
    ok = cell >= 0
    key = np.unique(bins[ok] * grid.n_cells + cell[ok])  # one vote per (bin, cell)
    b, c = np.divmod(key, grid.n_cells)
    return Votes(bin_index=b, cell=c, n_bins=n)


def _check_finite(**arrays: FloatArray) -> None:
    """A ValueError naming the first of ``arrays`` that holds a NaN or an infinity (the
    compiled kernel's cell arithmetic has no meaning for them)."""
    for name, a in arrays.items():
        if not np.all(np.isfinite(a)):
            raise ValueError(f"{name} holds a non-finite value")


#: The votes of no bins.
_NO_VOTES = Votes(np.empty(0, dtype=np.int64), np.empty(0, dtype=np.int64), 0)


def _arc_model(
    grid: HoughGrid, beam_width_rad: float, incidence_beta_rad: float
) -> tuple[float, float, int]:
    """``(alpha / 2, beta, K)`` of :func:`vote_arc` and its compiled twin: ``K`` theta cells
    cover a bin's span of line normals ``[theta_S - alpha/2 - beta, theta_S + alpha/2 + beta]``
    wherever it starts; a ValueError unless ``alpha + 2 beta < pi``."""
    half_a, beta = 0.5 * beam_width_rad, incidence_beta_rad
    if 2.0 * (half_a + beta) >= np.pi:
        raise ValueError("the sonar model needs alpha + 2 beta < pi")
    return half_a, beta, int(np.floor(2.0 * (half_a + beta) / grid.theta_res_rad)) + 2


def vote_arc(
    x_m: FloatArray,
    y_m: FloatArray,
    bearing_rad: FloatArray,
    range_m: FloatArray,
    grid: HoughGrid,
    beam_width_rad: float,
    incidence_beta_rad: float,
) -> Votes:
    """Votes of the continuous arc: eqs. 2-4 in the limit ``h, p -> infinity``.

    A bin votes once for every cell ``(theta cell, rho cell)`` that holds a line of normal ``theta``
    through a point of its arc at bearing ``theta_h`` with ``theta_h`` in
    ``[theta_S - alpha/2, theta_S + alpha/2]`` (eq. 2) and ``|theta - theta_h| <= beta`` (eq. 3). For a
    normal ``theta``, eq. 4 sweeps ``x_S cos theta + y_S sin theta + rho_S [min cos(u), max cos(u)]`` over
    the allowed ``u = theta - theta_h``; the union over the normals of a theta cell is taken as the hull
    of the intervals at its two ends and its middle.

    Parameters
    ----------
    x_m, y_m, bearing_rad, range_m : ndarray, shape (N,)
        Per bin: sensor position in R (m), beam-axis bearing in R (rad), range (m).
    grid : HoughGrid
    beam_width_rad, incidence_beta_rad : float
        ``alpha`` and ``beta`` (rad); ``alpha + 2 beta`` must be below ``pi``.

    Returns
    -------
    Votes
    """
    _check_finite(x_m=x_m, y_m=y_m, bearing_rad=bearing_rad, range_m=range_m)
    n = int(range_m.shape[0])
    half_a, beta, k = _arc_model(grid, beam_width_rad, incidence_beta_rad)
    dth, drho, nt, nr = grid.theta_res_rad, grid.rho_res_m, grid.n_theta, grid.n_rho
    if n == 0:
        return _NO_VOTES
    # theta cells meeting the span of line normals [theta_S - alpha/2 - beta, .. + beta] (eqs. 2-3)
    span_lo = (bearing_rad - half_a - beta)[:, None]
    span_hi = (bearing_rad + half_a + beta)[:, None]
    j_lo = np.floor((span_lo[:, 0] + np.pi) / dth).astype(np.int64)
    jj = j_lo[:, None] + np.arange(k)[None, :]  # (N, K), unwrapped; cell jj mod nt
    edge = -np.pi + jj * dth
    t_a = np.maximum(edge, span_lo)  # the part of the cell inside the span
    t_b = np.minimum(edge + dth, span_hi)
    ok = t_a <= t_b
    t_c = 0.5 * (t_a + t_b)
    th_s, r = bearing_rad[:, None], range_m[:, None]
    xs, ys = x_m[:, None], y_m[:, None]
    rho_lo = np.full(jj.shape, np.inf)
    rho_hi = np.full(jj.shape, -np.inf)
    for t in (t_a, t_c, t_b):  # ends and middle of the cell's normals (eq. 3, continuous)
        # arc bearings allowed for the normal t: eq. 2 and |t - theta_h| <= beta (eq. 3)
        h_lo = np.maximum(th_s - half_a, t - beta)
        h_hi = np.minimum(th_s + half_a, t + beta)
        u_lo, u_hi = t - h_hi, t - h_lo  # u = t - theta_h in [-beta, beta]
        a_lo, a_hi = np.abs(u_lo), np.abs(u_hi)
        cos_max = np.where((u_lo <= 0.0) & (u_hi >= 0.0), 1.0, np.cos(np.minimum(a_lo, a_hi)))
        cos_min = np.cos(np.maximum(a_lo, a_hi))
        c0 = xs * np.cos(t) + ys * np.sin(t)
        np.minimum(rho_lo, c0 + r * cos_min, out=rho_lo)  # eq. 4 over the allowed arc
        np.maximum(rho_hi, c0 + r * cos_max, out=rho_hi)
    jcell = jj % nt
    bins = np.broadcast_to(np.arange(n, dtype=np.int64)[:, None], jj.shape)
    # rho >= 0 part at theta_j; rho < 0 part is the line (-rho, theta_j + pi)
    pos = ok & (rho_hi >= 0.0)
    neg = ok & (rho_lo < 0.0)
    seg_lo = np.concatenate([np.maximum(rho_lo[pos], 0.0), np.maximum(-rho_hi[neg], 0.0)])
    seg_hi = np.concatenate([rho_hi[pos], -rho_lo[neg]])
    seg_j = np.concatenate([jcell[pos], (jcell[neg] + nt // 2) % nt])
    seg_b = np.concatenate([bins[pos], bins[neg]])
    i_lo = np.floor(seg_lo / drho).astype(np.int64)
    i_hi = np.minimum(np.floor(seg_hi / drho).astype(np.int64), nr - 1)
    keep = i_lo <= i_hi
    i_lo, i_hi, seg_j, seg_b = i_lo[keep], i_hi[keep], seg_j[keep], seg_b[keep]
    counts = i_hi - i_lo + 1
    total = int(counts.sum())
    seg = np.repeat(np.arange(counts.size), counts)
    starts = np.cumsum(counts) - counts
    i = i_lo[seg] + (np.arange(total) - starts[seg])
    return Votes(bin_index=seg_b[seg], cell=seg_j[seg] * nr + i, n_bins=n)


@numba.njit(cache=True, nogil=True)
def _arc_intervals(
    x_m: FloatArray,
    y_m: FloatArray,
    bearing_rad: FloatArray,
    range_m: FloatArray,
    half_a: float,
    beta: float,
    dth: float,
    drho: float,
    nt: int,
    nr: int,
    k: int,
) -> tuple[npt.NDArray[np.int64], npt.NDArray[np.int64], npt.NDArray[np.int64], npt.NDArray[np.int64]]:  # fmt: skip
    """:func:`vote_arc`'s rho intervals: per ``(bin, theta cell)`` its ``(bin, theta cell,
    first rho cell, last rho cell)``, first every rho >= 0 part in (bin, cell) order, then
    every rho < 0 part (the line ``(-rho, theta + pi)``); the same operations in the same
    order as :func:`vote_arc`."""
    n = range_m.shape[0]
    rho_lo = np.empty((n, k))
    rho_hi = np.empty((n, k))
    jcell = np.empty((n, k), dtype=np.int64)
    ok = np.empty((n, k), dtype=np.bool_)
    j_lo = np.empty(n, dtype=np.int64)
    for b in range(n):
        j_lo[b] = int(np.floor((bearing_rad[b] - half_a - beta + np.pi) / dth))
    # cos and sin of the cells' edges, which most t_a and t_b are: the same values, once
    j0 = j_lo.min()
    n_edges = j_lo.max() - j0 + k
    edge = np.empty(n_edges)
    cos_a, sin_a = np.empty(n_edges), np.empty(n_edges)
    cos_b, sin_b = np.empty(n_edges), np.empty(n_edges)
    for e in range(n_edges):
        edge[e] = -np.pi + (j0 + e) * dth
        cos_a[e], sin_a[e] = np.cos(edge[e]), np.sin(edge[e])
        cos_b[e], sin_b[e] = np.cos(edge[e] + dth), np.sin(edge[e] + dth)
    ts = np.empty(3)
    cs = np.empty(3)
    sn = np.empty(3)
    for b in range(n):
        th_s, r, xs, ys = bearing_rad[b], range_m[b], x_m[b], y_m[b]
        span_lo = th_s - half_a - beta
        span_hi = th_s + half_a + beta
        for q in range(k):
            jj = j_lo[b] + q
            e = jj - j0
            t_a = max(edge[e], span_lo)
            t_b = min(edge[e] + dth, span_hi)
            ok[b, q] = t_a <= t_b
            jcell[b, q] = jj % nt
            if not t_a <= t_b:
                continue  # no part of the cell in the span: not voted for
            t_c = 0.5 * (t_a + t_b)
            ts[0], ts[1], ts[2] = t_a, t_c, t_b
            if t_a == edge[e]:
                cs[0], sn[0] = cos_a[e], sin_a[e]
            else:
                cs[0], sn[0] = np.cos(t_a), np.sin(t_a)
            cs[1], sn[1] = np.cos(t_c), np.sin(t_c)
            if t_b == edge[e] + dth:
                cs[2], sn[2] = cos_b[e], sin_b[e]
            else:
                cs[2], sn[2] = np.cos(t_b), np.sin(t_b)
            lo, hi = np.inf, -np.inf
            for m in range(3):
                t = ts[m]
                h_lo = max(th_s - half_a, t - beta)
                h_hi = min(th_s + half_a, t + beta)
                u_lo, u_hi = t - h_hi, t - h_lo
                a_lo, a_hi = abs(u_lo), abs(u_hi)
                cos_max = 1.0 if (u_lo <= 0.0 and u_hi >= 0.0) else np.cos(min(a_lo, a_hi))
                cos_min = np.cos(max(a_lo, a_hi))
                c0 = xs * cs[m] + ys * sn[m]
                lo = min(lo, c0 + r * cos_min)
                hi = max(hi, c0 + r * cos_max)
            rho_lo[b, q], rho_hi[b, q] = lo, hi
    seg_b = np.empty(2 * n * k, dtype=np.int64)
    seg_j = np.empty(2 * n * k, dtype=np.int64)
    seg_lo = np.empty(2 * n * k, dtype=np.int64)
    seg_hi = np.empty(2 * n * k, dtype=np.int64)
    m = 0
    for side in range(2):
        for b in range(n):
            for q in range(k):
                if not ok[b, q]:
                    continue
                if side == 0:
                    if not rho_hi[b, q] >= 0.0:
                        continue
                    lo_m, hi_m, j = max(rho_lo[b, q], 0.0), rho_hi[b, q], jcell[b, q]
                else:
                    if not rho_lo[b, q] < 0.0:
                        continue
                    lo_m, hi_m = max(-rho_hi[b, q], 0.0), -rho_lo[b, q]
                    j = (jcell[b, q] + nt // 2) % nt
                i_lo = int(np.floor(lo_m / drho))
                i_hi = min(int(np.floor(hi_m / drho)), nr - 1)
                if i_lo <= i_hi:
                    seg_b[m], seg_j[m], seg_lo[m], seg_hi[m] = b, j, i_lo, i_hi
                    m += 1
    return seg_b[:m], seg_j[:m], seg_lo[:m], seg_hi[:m]


@numba.njit(cache=True, nogil=True)
def _expand_intervals(
    seg_b: npt.NDArray[np.int64],
    seg_j: npt.NDArray[np.int64],
    seg_lo: npt.NDArray[np.int64],
    seg_hi: npt.NDArray[np.int64],
    nr: int,
) -> tuple[npt.NDArray[np.int64], npt.NDArray[np.int64]]:
    """One vote ``(bin, flat cell)`` per rho cell of each interval, in order."""
    total = 0
    for s in range(seg_b.shape[0]):
        total += seg_hi[s] - seg_lo[s] + 1
    bins = np.empty(total, dtype=np.int64)
    cells = np.empty(total, dtype=np.int64)
    v = 0
    for s in range(seg_b.shape[0]):
        for i in range(seg_lo[s], seg_hi[s] + 1):
            bins[v] = seg_b[s]
            cells[v] = seg_j[s] * nr + i
            v += 1
    return bins, cells


def vote_arc_compiled(
    x_m: FloatArray,
    y_m: FloatArray,
    bearing_rad: FloatArray,
    range_m: FloatArray,
    grid: HoughGrid,
    beam_width_rad: float,
    incidence_beta_rad: float,
) -> Votes:
    """:func:`vote_arc` compiled (the module docstring): the same votes in the same order.

    Parameters and returns are :func:`vote_arc`'s.
    """
    _check_finite(x_m=x_m, y_m=y_m, bearing_rad=bearing_rad, range_m=range_m)
    n = int(range_m.shape[0])
    half_a, beta, k = _arc_model(grid, beam_width_rad, incidence_beta_rad)
    if n == 0:
        return _NO_VOTES
    dth = grid.theta_res_rad
    f64 = np.float64
    seg = _arc_intervals(
        np.ascontiguousarray(x_m, dtype=f64),
        np.ascontiguousarray(y_m, dtype=f64),
        np.ascontiguousarray(bearing_rad, dtype=f64),
        np.ascontiguousarray(range_m, dtype=f64),
        float(half_a),
        float(beta),
        float(dth),
        float(grid.rho_res_m),
        grid.n_theta,
        grid.n_rho,
        k,
    )
    bins, cells = _expand_intervals(*seg, grid.n_rho)
    return Votes(bin_index=bins, cell=cells, n_bins=n)


def accumulate(votes: Votes, grid: HoughGrid) -> npt.NDArray[np.int64]:
    """The accumulator: votes per cell, shape ``(n_theta, n_rho)``."""
    acc = np.bincount(votes.cell, minlength=grid.n_cells)
    return acc.reshape(grid.shape).astype(np.int64)


def find_winners(
    votes: Votes,
    grid: HoughGrid,
    min_votes: int,
    max_winners: int = 32,
    suppress_theta_cells: int = 1,
    suppress_rho_cells: int = 1,
) -> tuple[list[Winner], npt.NDArray[np.int64]]:
    """Winning cells of a vote, best first (paper 2.5), by a compiled search.

    The same winners, voters and removed bins as :func:`find_winners_reference` (integer
    work only; ``tests/test_hough.py``), without ten array passes over the whole grid per
    winner. Parameters and returns are its.
    """
    acc0 = accumulate(votes, grid)
    if votes.cell.size == 0 or max_winners <= 0:
        return [], acc0
    cells, n_votes, voters, v_off, removed, r_off = _winners_kernel(
        np.ascontiguousarray(votes.bin_index, dtype=np.int64),
        np.ascontiguousarray(votes.cell, dtype=np.int64),
        acc0.reshape(-1).copy(),
        int(votes.n_bins),
        grid.n_theta,
        grid.n_rho,
        int(max(min_votes, 1)),
        int(max_winners),
        int(suppress_theta_cells),
        int(suppress_rho_cells),
    )
    winners: list[Winner] = []
    for w in range(cells.size):
        rho, theta = grid.cell_center(int(cells[w]))
        winners.append(
            Winner(
                cell=int(cells[w]),
                rho_m=float(rho),
                theta_rad=float(theta),
                votes=int(n_votes[w]),
                voters=voters[v_off[w] : v_off[w + 1]].copy(),
                removed=removed[r_off[w] : r_off[w + 1]].copy(),
            )
        )
    return winners, acc0


@numba.njit(cache=True, nogil=True)
def _winners_kernel(
    bin_index: IntArray,
    cell: IntArray,
    acc: IntArray,
    n_bins: int,
    n_theta: int,
    n_rho: int,
    min_votes: int,
    max_winners: int,
    sup_j: int,
    sup_i: int,
) -> tuple[IntArray, IntArray, IntArray, IntArray, IntArray, IntArray]:
    """:func:`find_winners_reference`'s loop: per winner its cell, votes, sorted voters and
    sorted removed bins (flat, with offsets)."""
    nv = cell.shape[0]
    active = np.ones(nv, dtype=np.bool_)
    removed_bin = np.zeros(n_bins, dtype=np.bool_)
    in_win = np.zeros(n_bins, dtype=np.bool_)
    is_voter = np.zeros(n_bins, dtype=np.bool_)
    window = np.zeros(n_theta * n_rho, dtype=np.bool_)
    # a bin is removed once (its votes go with it), and every winner removes one at least
    cap = min(max_winners, n_bins)
    cells = np.empty(cap, dtype=np.int64)
    counts = np.empty(cap, dtype=np.int64)
    voters = np.empty(n_bins, dtype=np.int64)
    removed = np.empty(n_bins, dtype=np.int64)
    v_off = np.zeros(cap + 1, dtype=np.int64)
    r_off = np.zeros(cap + 1, dtype=np.int64)
    nw = 0
    while nw < cap:
        c = 0  # argmax: the first cell of the most votes
        for q in range(acc.shape[0]):
            if acc[q] > acc[c]:
                c = q
        if acc[c] < min_votes:
            break
        cells[nw], counts[nw] = c, acc[c]
        j, i = c // n_rho, c % n_rho
        for dj in range(-sup_j, sup_j + 1):
            for di in range(-sup_i, sup_i + 1):
                if 0 <= i + di < n_rho:
                    window[((j + dj) % n_theta) * n_rho + i + di] = True
        for v in range(nv):
            if active[v]:
                if cell[v] == c:
                    is_voter[bin_index[v]] = True
                if window[cell[v]]:
                    in_win[bin_index[v]] = True
        for dj in range(-sup_j, sup_j + 1):
            for di in range(-sup_i, sup_i + 1):
                if 0 <= i + di < n_rho:
                    window[((j + dj) % n_theta) * n_rho + i + di] = False
        nvo, nre = v_off[nw], r_off[nw]
        for b in range(n_bins):  # sorted and unique, as np.unique
            if is_voter[b]:
                voters[nvo] = b
                nvo += 1
            if is_voter[b] or in_win[b]:
                removed[nre] = b
                nre += 1
                removed_bin[b] = True
            is_voter[b] = False
            in_win[b] = False
        v_off[nw + 1], r_off[nw + 1] = nvo, nre
        for v in range(nv):
            if active[v] and removed_bin[bin_index[v]]:
                acc[cell[v]] -= 1
                active[v] = False
        nw += 1
    return cells[:nw], counts[:nw], voters, v_off[: nw + 1], removed, r_off[: nw + 1]


def find_winners_reference(
    votes: Votes,
    grid: HoughGrid,
    min_votes: int,
    max_winners: int = 32,
    suppress_theta_cells: int = 1,
    suppress_rho_cells: int = 1,
) -> tuple[list[Winner], npt.NDArray[np.int64]]:
    """:func:`find_winners` vectorised in numpy: the reference of the compiled search.

    Winning cells of a vote, best first (paper 2.5).

    Repeat: the cell with most votes wins if it has at least ``min_votes``; its voters and the
    bins that voted for a cell within ``+-suppress_theta_cells`` x ``+-suppress_rho_cells`` of it
    are removed and all their votes are taken off the accumulator.

    Parameters
    ----------
    votes : Votes
    grid : HoughGrid
    min_votes : int
        Votes needed by a winner.
    max_winners : int
        Most winners returned.
    suppress_theta_cells, suppress_rho_cells : int
        Half sizes of the suppression window (cells); 0 removes the voters only.

    Returns
    -------
    winners : list of Winner
    accumulator : ndarray of int64, shape (n_theta, n_rho)
        The accumulator before any removal.
    """
    acc0 = accumulate(votes, grid)
    acc = acc0.reshape(-1).copy()
    active = np.ones(votes.cell.shape[0], dtype=bool)
    removed_bin = np.zeros(votes.n_bins, dtype=bool)
    winners: list[Winner] = []
    dj = np.arange(-suppress_theta_cells, suppress_theta_cells + 1)
    di = np.arange(-suppress_rho_cells, suppress_rho_cells + 1)
    window = np.zeros(grid.n_cells, dtype=bool)
    while len(winners) < max_winners and acc.size:
        c = int(np.argmax(acc))
        n_votes = int(acc[c])
        if n_votes < max(min_votes, 1):
            break
        voters = np.unique(votes.bin_index[active & (votes.cell == c)])
        j, i = divmod(c, grid.n_rho)
        wj = (j + dj) % grid.n_theta
        wi = i + di
        wi = wi[(wi >= 0) & (wi < grid.n_rho)]
        wcells = (wj[:, None] * grid.n_rho + wi[None, :]).ravel()
        window[wcells] = True
        in_window = active & window[votes.cell]
        window[wcells] = False
        removed_bin[votes.bin_index[in_window]] = True
        removed_bin[voters] = True
        gone = active & removed_bin[votes.bin_index]
        acc -= np.bincount(votes.cell[gone], minlength=grid.n_cells)
        active &= ~gone
        removed = np.unique(np.concatenate([voters, votes.bin_index[in_window]]))
        rho, theta = grid.cell_center(c)
        winners.append(
            Winner(
                cell=c,
                rho_m=float(rho),
                theta_rad=float(theta),
                votes=n_votes,
                voters=voters,
                removed=removed,
            )
        )
    return winners, acc0


def _load_kernels() -> None:
    """Load the compiled kernels from numba's cache (compile them, the first time on a
    machine) at import, for the argument types a vote passes: not inside a run's first vote."""
    one = np.ones(1)
    seg = _arc_intervals(one, one, one, one, 0.01, 0.1, 0.05, 0.1, 4, 4, 4)
    _expand_intervals(*seg, 4)
    i1 = np.zeros(1, dtype=np.int64)
    _winners_kernel(i1, i1, np.ones(4, dtype=np.int64), 1, 2, 2, 1, 1, 0, 0)


_load_kernels()
