"""Beam pre-processing, one beam at a time (design.md step 1, paper section 2.1).

Three stages, each vectorised over the bins of the beam:

a. **threshold**: keep the bins whose intensity is at least ``intensity_threshold``. These
   *threshold bins* are kept apart: the uncertainty step (paper 2.6) counts them.
b. **maximum intensity difference**: of the threshold bins, keep those whose intensity is within
   ``max_intensity_difference`` of the strongest bin of the beam.
c. **sparseness**: of two kept bins closer than ``min_distance_m``, drop the weaker; on a tie of
   intensity, keep the nearer. The rule is applied to every pair at once: a bin survives if and
   only if no *stronger* kept bin (higher intensity, or equal intensity and nearer) lies closer
   than ``min_distance_m``. The survivors are the *final bins*, the voters of the Hough step.

Bins nearer than ``min_range_m`` (the near-field dead zone: transducer ringing, the vehicle's own
hull) take no part in any stage.

A beam of uint8 intensities (every reader's) goes through :func:`_segment_uint8`, the three
stages in one compiled loop (numba): integer comparisons only, so its bins are exactly those of
the vectorised stages (:func:`_segment_vectorised`, kept as the reference and for other dtypes;
``tests/test_segmentation.py``), at a small fraction of some fifteen numpy calls per beam.

Already-thresholded beams (:attr:`sonarslam.sonar.beam.SonarBeam.thresholded`, e.g. the marina keyframes,
whose intensities are a 0/255 mask made by a third party) go through the same three stages,
which then reduce to:

a. the threshold is the third party's: every non-zero bin (beyond ``min_range_m``) is a threshold
   bin, whatever ``intensity_threshold`` says;
b. all given bins have the same intensity, so the maximum-intensity-difference stage keeps all;
c. with all intensities equal, the tie rule (keep the nearer) decides every pair, so the
   sparseness stage keeps the **nearest bin of each run**, a run being a chain of given bins
   whose gaps are all shorter than ``min_distance_m``. This is the first return of each echo.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache
from typing import Any

import numba
import numpy as np
import numpy.typing as npt
from scipy.ndimage import maximum_filter1d

from sonarslam.sonar.beam import SonarBeam, SonarHead, beam_bin_size_m, bin_range_m

__all__ = ["SegmentedBeam", "segment_intensities", "segment_beam", "leading_edge_bins"]

IntArray = npt.NDArray[np.int64]


@dataclass(frozen=True, eq=False)
class SegmentedBeam:
    """The bins of one beam that survive each stage of the segmentation.

    Attributes
    ----------
    threshold_bins : ndarray of int64, shape (M,)
        0-based bin indices that passed the threshold stage (a), increasing.
    final_bins : ndarray of int64, shape (K,)
        0-based bin indices that passed all three stages, increasing; a subset of
        ``threshold_bins``.
    final_intensities : ndarray of uint8, shape (K,)
        Intensities of the final bins (0-255).
    """

    threshold_bins: IntArray
    final_bins: IntArray
    final_intensities: npt.NDArray[np.uint8]


def _sparse_window_bins(min_distance_m: float, bin_size_m: float) -> int:
    """Largest bin-index gap ``k`` with ``k * bin_size_m < min_distance_m`` (0 if none)."""
    ratio = min_distance_m / bin_size_m
    # Two bins k indices apart are closer than min_distance_m iff k < ratio; the tolerance keeps
    # 0.5 m / 0.1 m from counting as 5.000000000000001.
    return max(int(np.ceil(ratio - 1e-9)) - 1, 0)


@lru_cache(maxsize=32)
def _alive_bins(
    n_bins: int, bin_size_m: float, min_range_m: float, max_range_m: float | None
) -> npt.NDArray[np.bool_]:
    """Bins inside ``[min_range_m, max_range_m]`` (read-only; one per beam geometry)."""
    ranges_m = bin_range_m(np.arange(n_bins), bin_size_m)
    alive = ranges_m >= min_range_m - 1e-9 * bin_size_m
    if max_range_m is not None:
        alive &= ranges_m <= max_range_m + 1e-9 * bin_size_m
    alive.flags.writeable = False
    return alive


def segment_intensities(
    intensities: npt.ArrayLike,
    bin_size_m: float,
    *,
    intensity_threshold: float,
    max_intensity_difference: float,
    min_distance_m: float,
    min_range_m: float = 0.0,
    thresholded: bool = False,
    max_range_m: float | None = None,
) -> SegmentedBeam:
    """Segment the intensity profile of one beam (paper 2.1).

    Parameters
    ----------
    intensities : array_like, shape (n_bins,)
        Echo intensity per bin (0-255); bin ``i`` is at range ``(i + 1) * bin_size_m``.
    bin_size_m : float
        Range step between bins (m).
    intensity_threshold : float
        Stage (a): bins with intensity ``>=`` this are threshold bins. Ignored when
        ``thresholded`` (every non-zero bin is one).
    max_intensity_difference : float
        Stage (b): keep the threshold bins with intensity ``>= max - max_intensity_difference``.
    min_distance_m : float
        Stage (c): of two kept bins closer than this (m), drop the weaker (ties: the farther).
        0 disables the stage.
    min_range_m : float
        Near-field dead zone (m): bins at a range below this are ignored by every stage.
    thresholded : bool
        True when ``intensities`` is already a 0/255 mask (see the module docstring).
    max_range_m : float, optional
        Bins beyond this range (m) are ignored by every stage; None: all.

    Returns
    -------
    SegmentedBeam
    """
    inten = np.asarray(intensities)
    n_bins = inten.shape[0]
    alive = _alive_bins(n_bins, bin_size_m, min_range_m, max_range_m)
    k = _sparse_window_bins(min_distance_m, bin_size_m)
    if inten.dtype == np.uint8 and inten.ndim == 1:
        threshold_bins, kept = _segment_uint8(
            inten,
            alive,
            bool(thresholded),
            float(intensity_threshold),
            float(max_intensity_difference),
            k,
        )
        return SegmentedBeam(threshold_bins, kept, inten[kept])
    return _segment_vectorised(
        inten, alive, thresholded, intensity_threshold, max_intensity_difference, k
    )


def _segment_vectorised(
    inten: npt.NDArray[Any],
    alive: npt.NDArray[np.bool_],
    thresholded: bool,
    intensity_threshold: float,
    max_intensity_difference: float,
    k: int,
) -> SegmentedBeam:
    """The three stages vectorised over the bins (the reference of :func:`_segment_uint8`);
    ``k`` is :func:`_sparse_window_bins`'."""
    n_bins = inten.shape[0]
    # (a) threshold stage
    if thresholded:
        passed = alive & (inten > 0)
    else:
        passed = alive & (inten >= intensity_threshold)
    threshold_bins = np.flatnonzero(passed).astype(np.int64)
    if threshold_bins.size == 0:
        empty = np.empty(0, dtype=np.int64)
        return SegmentedBeam(threshold_bins, empty, np.empty(0, dtype=np.uint8))
    # (b) maximum intensity difference to the strongest bin of the beam
    thr_int = inten[threshold_bins].astype(np.int64)
    kept = threshold_bins[thr_int >= thr_int.max() - max_intensity_difference]
    # (c) sparseness: a kept bin survives iff it holds the strongest key within the window of
    # bins closer than min_distance_m. Key = intensity, ties broken towards the nearer bin; keys
    # are unique, so a bin and a stronger neighbour never both survive.
    kept_int = inten[kept]
    if k > 0 and kept.size > 1 and kept_int.min() == kept_int.max():
        # Equal keys but for the tie-break (a mask): a bin survives iff no kept bin lies
        # within k bins nearer, i.e. the nearest bin of each chain with gaps <= k.
        kept = kept[np.diff(kept, prepend=kept[0] - k - 1) > k]
    elif k > 0 and kept.size > 1:
        key = np.full(n_bins, -1, dtype=np.int64)
        key[kept] = inten[kept].astype(np.int64) * (n_bins + 1) + (n_bins - kept)
        local_max = maximum_filter1d(key, size=2 * k + 1, mode="constant", cval=-1)
        kept = kept[local_max[kept] == key[kept]]
    return SegmentedBeam(
        threshold_bins=threshold_bins,
        final_bins=kept,
        final_intensities=inten[kept].astype(np.uint8),
    )


@numba.njit(cache=True, nogil=True)
def _segment_uint8(
    inten: npt.NDArray[np.uint8],
    alive: npt.NDArray[np.bool_],
    thresholded: bool,
    intensity_threshold: float,
    max_intensity_difference: float,
    k: int,
) -> tuple[IntArray, IntArray]:
    """Stages (a)-(c) of one uint8 beam in one pass each: ``(threshold_bins, final_bins)``, the
    same as :func:`_segment_vectorised`'s. Stage (c) keeps a bin iff no kept bin within ``k``
    bins has a larger key (intensity, then nearer), which is the maximum filter's rule (and, on
    equal intensities, the nearest bin of each chain)."""
    n = inten.shape[0]
    tb = np.empty(n, dtype=np.int64)
    m = 0
    top = -1
    for i in range(n):
        v = inten[i]
        if alive[i] and ((v > 0) if thresholded else (v >= intensity_threshold)):
            tb[m] = i
            m += 1
            if int(v) > top:
                top = int(v)
    kept = np.empty(m, dtype=np.int64)
    n_kept = 0
    floor = top - max_intensity_difference
    for q in range(m):
        if inten[tb[q]] >= floor:
            kept[n_kept] = tb[q]
            n_kept += 1
    if k <= 0 or n_kept <= 1:
        return tb[:m], kept[:n_kept]
    final = np.empty(n_kept, dtype=np.int64)
    n_final = 0
    for q in range(n_kept):
        i = kept[q]
        key = np.int64(inten[i]) * (n + 1) + (n - i)
        wins = True
        p = q - 1
        while wins and p >= 0 and i - kept[p] <= k:
            wins = np.int64(inten[kept[p]]) * (n + 1) + (n - kept[p]) < key
            p -= 1
        p = q + 1
        while wins and p < n_kept and kept[p] - i <= k:
            wins = np.int64(inten[kept[p]]) * (n + 1) + (n - kept[p]) < key
            p += 1
        if wins:
            final[n_final] = i
            n_final += 1
    return tb[:m], final[:n_final]


def segment_beam(
    beam: SonarBeam,
    head: SonarHead,
    *,
    intensity_threshold: float,
    max_intensity_difference: float,
    min_distance_m: float,
    min_range_m: float = 0.0,
    max_range_m: float | None = None,
) -> SegmentedBeam:
    """Segment a :class:`~sonarslam.sonar.beam.SonarBeam` with its head settings (its own bin
    size when it has one, :func:`~sonarslam.sonar.beam.beam_bin_size_m`).

    See :func:`segment_intensities`; ``beam.thresholded`` selects the mask behaviour.
    """
    return segment_intensities(
        beam.intensities,
        beam_bin_size_m(beam, head),
        intensity_threshold=intensity_threshold,
        max_intensity_difference=max_intensity_difference,
        min_distance_m=min_distance_m,
        min_range_m=min_range_m,
        thresholded=beam.thresholded,
        max_range_m=max_range_m,
    )


def leading_edge_bins(
    beam: SonarBeam,
    head: SonarHead,
    *,
    run_gap_m: float,
    min_range_m: float,
    max_range_m: float | None = None,
    intensity_threshold: float = 60.0,
) -> IntArray:
    """The leading edge of each run of returns of one beam: where a wall's face is.

    A wall's echo is a band of returns metres thick along a beam, its near edge on the wall's
    face. The returns (a mask's non-zero bins; a raw beam's bins at or above
    ``intensity_threshold``) are cut into runs, chains whose gaps are shorter than
    ``run_gap_m``, and the nearest bin of each run is kept: stage (c) of
    :func:`segment_intensities` with all returns equal (the module docstring). The one rule of
    the wall references (:mod:`sonarslam.slam.eval.leading_edges`) and the scan matcher
    (:mod:`sonarslam.features.scans`).

    Parameters
    ----------
    beam : SonarBeam
    head : SonarHead
        Its bin size, unless the beam has its own.
    run_gap_m : float
        Returns closer than this along the beam are one run (m).
    min_range_m : float
        Bins nearer than this are ignored (m).
    max_range_m : float, optional
        Bins farther than this are ignored (m); None: all.
    intensity_threshold : float
        Raw beams: a bin at or above this is a return (masks: every non-zero bin).

    Returns
    -------
    ndarray of int64, shape (K,)
        0-based bin indices of the leading edges, increasing.
    """
    inten = beam.intensities
    given = inten > 0 if beam.thresholded else inten >= intensity_threshold
    seg = segment_intensities(
        np.where(given, 255, 0).astype(np.uint8),
        beam_bin_size_m(beam, head),
        intensity_threshold=1.0,
        max_intensity_difference=0.0,
        min_distance_m=run_gap_m,
        min_range_m=min_range_m,
        thresholded=True,  # all returns equal: the sparseness keeps the nearest of each run
        max_range_m=max_range_m,
    )
    return seg.final_bins


def _load_kernel() -> None:
    """Load :func:`_segment_uint8` from numba's cache (compile it, the first time on a
    machine) at import, for a beam's argument types: not inside a run's first beam."""
    _segment_uint8(np.zeros(2, dtype=np.uint8), _alive_bins(2, 1.0, 0.0, None), False, 1.0, 0.0, 1)


_load_kernel()
