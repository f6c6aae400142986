"""Beam segmentation (paper 2.1): each stage on hand-made beams."""

from __future__ import annotations

import numpy as np
import pytest

from sonarslam.sonar.beam import SonarBeam, SonarHead
from sonarslam.sonar.segmentation import (
    _alive_bins,
    _segment_uint8,
    _segment_vectorised,
    _sparse_window_bins,
    segment_beam,
    segment_intensities,
)

BIN_M = 0.1


def _beam(n: int, values: dict[int, int]) -> np.ndarray:
    b = np.zeros(n, dtype=np.uint8)
    for i, v in values.items():
        b[i] = v
    return b


def test_threshold_stage_keeps_bins_at_or_above_threshold() -> None:
    b = _beam(50, {5: 79, 6: 80, 7: 200, 30: 120})
    seg = segment_intensities(
        b, BIN_M, intensity_threshold=80, max_intensity_difference=255, min_distance_m=0.0
    )
    np.testing.assert_array_equal(seg.threshold_bins, [6, 7, 30])
    np.testing.assert_array_equal(seg.final_bins, [6, 7, 30])
    np.testing.assert_array_equal(seg.final_intensities, [80, 200, 120])


def test_max_intensity_difference_keeps_bins_near_the_beam_maximum() -> None:
    b = _beam(50, {10: 100, 20: 200, 30: 170, 40: 169})
    seg = segment_intensities(
        b, BIN_M, intensity_threshold=50, max_intensity_difference=30, min_distance_m=0.0
    )
    np.testing.assert_array_equal(seg.threshold_bins, [10, 20, 30, 40])
    np.testing.assert_array_equal(seg.final_bins, [20, 30])


def test_sparseness_drops_the_weaker_of_close_bins() -> None:
    # 0.5 m = 5 bins: bins 4 apart are close, 5 apart are not
    b = _beam(60, {10: 150, 14: 200, 19: 150, 40: 180, 45: 181})
    seg = segment_intensities(
        b, BIN_M, intensity_threshold=50, max_intensity_difference=255, min_distance_m=0.5
    )
    # 10 is 0.4 m from the stronger 14; 19 is 0.5 m from 14 (not closer); 40 and 45 are 0.5 m
    np.testing.assert_array_equal(seg.final_bins, [14, 19, 40, 45])
    seg = segment_intensities(
        b, BIN_M, intensity_threshold=50, max_intensity_difference=255, min_distance_m=0.51
    )
    np.testing.assert_array_equal(seg.final_bins, [14, 45])


def test_sparseness_tie_keeps_the_nearer_bin() -> None:
    b = _beam(40, {10: 150, 12: 150, 30: 90})
    seg = segment_intensities(
        b, BIN_M, intensity_threshold=50, max_intensity_difference=255, min_distance_m=0.3
    )
    np.testing.assert_array_equal(seg.final_bins, [10, 30])


def test_near_field_dead_zone_is_ignored_by_every_stage() -> None:
    # a strong ringing bin at 0.3 m must neither pass nor set the beam maximum
    b = _beam(40, {2: 255, 20: 120, 25: 110})
    seg = segment_intensities(
        b,
        BIN_M,
        intensity_threshold=50,
        max_intensity_difference=20,
        min_distance_m=0.0,
        min_range_m=1.0,
    )
    np.testing.assert_array_equal(seg.threshold_bins, [20, 25])
    np.testing.assert_array_equal(seg.final_bins, [20, 25])
    # bin 9 is at exactly 1.0 m: inside the kept range
    seg = segment_intensities(
        _beam(40, {9: 100}),
        BIN_M,
        intensity_threshold=50,
        max_intensity_difference=20,
        min_distance_m=0.0,
        min_range_m=1.0,
    )
    np.testing.assert_array_equal(seg.threshold_bins, [9])


def test_empty_beam() -> None:
    seg = segment_intensities(
        np.zeros(30, dtype=np.uint8),
        BIN_M,
        intensity_threshold=50,
        max_intensity_difference=20,
        min_distance_m=0.5,
    )
    assert seg.threshold_bins.size == 0 and seg.final_bins.size == 0


def test_thresholded_mask_keeps_nearest_bin_of_each_run() -> None:
    head = SonarHead(n_bins=100, bin_size_m=BIN_M)
    mask = np.zeros(100, dtype=np.uint8)
    mask[20:35] = 255  # one 1.5 m run
    mask[37:40] = 255  # a gap of 0.3 m: same run for a 0.5 m min distance
    mask[60:62] = 255  # a separate run
    beam = SonarBeam(t=0.0, transducer_angle_rad=0.0, intensities=mask, thresholded=True)
    # the intensity threshold is the third party's: 255 > 0 passes whatever we set
    seg = segment_beam(
        beam, head, intensity_threshold=300, max_intensity_difference=0, min_distance_m=0.5
    )
    np.testing.assert_array_equal(seg.threshold_bins, np.flatnonzero(mask))
    np.testing.assert_array_equal(seg.final_bins, [20, 60])
    # a smaller min distance splits the run at the 0.3 m gap
    seg = segment_beam(
        beam, head, intensity_threshold=300, max_intensity_difference=0, min_distance_m=0.25
    )
    np.testing.assert_array_equal(seg.final_bins, [20, 37, 60])


@pytest.mark.parametrize(
    ("seed", "mask"), [(0, False), (1, False), (2, False), (3, True), (4, True)]
)
def test_sparseness_matches_the_pairwise_rule(seed: int, mask: bool) -> None:
    """Vectorised stage (c) against the pairwise definition, on random beams (raw, and masks:
    all returns equal, the path that keeps the nearest bin of each chain)."""
    rng = np.random.default_rng(seed)
    values = np.full(200, 255) if mask else rng.integers(0, 256, 200)
    b = np.where(rng.random(200) < 0.2, values, 0).astype(np.uint8)
    d_m = 0.45
    seg = segment_intensities(
        b, BIN_M, intensity_threshold=60, max_intensity_difference=120, min_distance_m=d_m
    )
    thr = np.flatnonzero(b >= 60)
    kept = thr[b[thr].astype(int) >= int(b[thr].max()) - 120]
    expect = []
    for i in kept:
        stronger_close = [
            j
            for j in kept
            if j != i and abs(j - i) * BIN_M < d_m and (b[j] > b[i] or (b[j] == b[i] and j < i))
        ]
        if not stronger_close:
            expect.append(i)
    np.testing.assert_array_equal(seg.final_bins, expect)


@pytest.mark.parametrize("seed", range(6))
def test_the_compiled_stages_give_the_vectorised_bins(seed: int) -> None:
    """:func:`_segment_uint8` (what uint8 beams go through) against the vectorised stages (the
    reference) on random raw beams and masks, dead zones, windows and thresholds."""
    rng = np.random.default_rng(seed)
    for _ in range(50):
        n = int(rng.integers(1, 400))
        mask = bool(rng.random() < 0.3)
        values = np.full(n, 255) if mask else rng.integers(0, 256, n)
        b = np.where(rng.random(n) < rng.uniform(0.0, 0.6), values, 0).astype(np.uint8)
        bin_m = float(rng.choice([0.05, 0.1, 0.3]))
        alive = _alive_bins(n, bin_m, float(rng.uniform(0.0, 2.0)), None)
        k = _sparse_window_bins(float(rng.choice([0.0, 0.1, 0.45, 1.0])), bin_m)
        thr, diff = float(rng.integers(0, 200)), float(rng.integers(0, 256))
        ref = _segment_vectorised(b, alive, mask, thr, diff, k)
        tb, final = _segment_uint8(b, alive, mask, thr, diff, k)
        np.testing.assert_array_equal(tb, ref.threshold_bins)
        np.testing.assert_array_equal(final, ref.final_bins)
        seg = segment_intensities(
            b, bin_m, intensity_threshold=thr, max_intensity_difference=diff, min_distance_m=0.45
        )
        assert seg.final_intensities.dtype == np.uint8
        np.testing.assert_array_equal(seg.final_intensities, b[seg.final_bins])


def test_bins_beyond_the_maximum_range_are_ignored_by_every_stage() -> None:
    # bin 29 (3.0 m) is the strongest: beyond max_range_m it must not set stage (b)'s maximum
    beam = _beam(40, {10: 100, 19: 90, 29: 250})
    kwargs = dict(intensity_threshold=50, max_intensity_difference=20, min_distance_m=0.0)
    seg = segment_intensities(beam, BIN_M, max_range_m=2.0, **kwargs)  # bin 19 is at 2.0 m
    np.testing.assert_array_equal(seg.threshold_bins, [10, 19])
    np.testing.assert_array_equal(seg.final_bins, [10, 19])
    seg = segment_intensities(beam, BIN_M, **kwargs)
    np.testing.assert_array_equal(seg.final_bins, [29])
