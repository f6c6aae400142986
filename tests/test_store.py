"""The sensor-frame ring buffer of beams (sonar/store.py): order, eviction, slots, removal."""

from __future__ import annotations

import numpy as np

from sonarslam.sonar.beam import SonarHead
from sonarslam.sonar.segmentation import SegmentedBeam
from sonarslam.sonar.store import SectorStore


def _segmented(bins: list[int]) -> SegmentedBeam:
    b = np.asarray(bins, dtype=np.int64)
    return SegmentedBeam(b, b, np.full(b.size, 200, dtype=np.uint8))


def test_store_keeps_the_last_sector_oldest_first_with_ranges_in_the_sensor_frame() -> None:
    head = SonarHead(n_bins=50, bin_size_m=0.2, step_rad=float(np.deg2rad(18.0)))
    store = SectorStore(head, sector_rad=np.pi)  # 10 beams
    assert store.capacity == 10
    slots = [store.add(100.0 + k, 0.1 * k, _segmented([k % 50, 40])) for k in range(13)]
    assert slots[:10] == list(range(10)) and slots[10:] == [0, 1, 2]  # the oldest evicted
    s = store.stored()
    np.testing.assert_allclose(s.t_s, 100.0 + np.arange(3, 13), atol=0.0)
    np.testing.assert_allclose(s.bearing_rad, 0.1 * np.arange(3, 13), atol=1e-15)
    assert s.slot.tolist() == [3, 4, 5, 6, 7, 8, 9, 0, 1, 2]
    # bin i is at (i + 1) * bin size, in the beam's own frame
    first = s.final.beam == 0
    np.testing.assert_allclose(np.sort(s.final.range_m[first]), [0.8, 8.2], atol=1e-12)
    assert len(s.threshold.range_m) == len(s.final.range_m) == 20
    store.remove_final_bins(s.final.bin_id[first])
    after = store.stored()
    assert len(after.final.range_m) == 18 and len(after.threshold.range_m) == 20


def test_a_calibrated_range_offset_moves_every_bin_to_the_surface(tmp_path) -> None:
    from sonarslam.datasets.config import DatasetConfig, dump_dataset_config, load_dataset_config

    head = SonarHead(n_bins=50, bin_size_m=0.1, range_offset_m=0.25)
    np.testing.assert_allclose(head.bin_range_m([9, 19]), [0.75, 1.75], atol=1e-12)
    assert head.range_to_bin([0.75, 1.75]).tolist() == [9, 19]
    store = SectorStore(head, sector_rad=np.pi)
    store.add(0.0, 0.0, _segmented([9]))
    np.testing.assert_allclose(store.stored().final.range_m, [0.75], atol=1e-12)
    # [sonar] range_offset_m round-trips through sonarslam.toml
    path = tmp_path / "sonarslam.toml"
    path.write_text(dump_dataset_config(DatasetConfig(sonar=head)))
    assert load_dataset_config(path).sonar.range_offset_m == 0.25


def test_a_beam_of_its_own_bin_size_is_placed_by_it_everywhere() -> None:
    """A log whose range changes (a Ping Viewer log's segments): the store, the projection,
    the scans and the beam series take each beam's own bin size, the head's where it has
    none (issue 41)."""
    from sonarslam.datasets.records import BeamSeries
    from sonarslam.features.geometry import FloatArray
    from sonarslam.features.projection import beam_points
    from sonarslam.features.scans.config import ScanConfig
    from sonarslam.features.scans.scan import ScanBuilder
    from sonarslam.sonar.beam import Mounting

    head = SonarHead(n_bins=50, bin_size_m=0.2, step_rad=float(np.pi / 2), range_offset_m=0.05)
    store = SectorStore(head, sector_rad=np.pi)
    store.add(0.0, 0.0, _segmented([9]), bin_size_m=0.01)  # a 0.5 m segment's beam
    store.add(1.0, 0.0, _segmented([9]))
    np.testing.assert_allclose(store.stored().final.range_m, [0.05, 1.95], atol=1e-12)
    rows = np.zeros((4, 50), np.uint8)
    rows[:, 9] = 200
    own = np.array([0.01, 0.01, 0.2, 0.2])
    series = BeamSeries(np.arange(4.0), np.zeros(4), rows, False, own)
    for beams in (series, list(series), series[1:], series.shifted(5.0).between(6.5, 9.0)):
        _, r, _ = beam_points(beams, head, 100)
        np.testing.assert_allclose(r, (10 * own - 0.05)[4 - len(beams) :], atol=1e-12)
    again = BeamSeries.of(list(series)).bin_size_m
    assert again is not None and again.tolist() == own.tolist()

    class Still:
        def poses(self, t_s: FloatArray) -> FloatArray:
            return np.zeros((np.size(t_s), 3))

        def covariance(self, t_s: float) -> None:
            return None

    config = ScanConfig(min_range_m=0.0, intensity_threshold=100.0)
    builder = ScanBuilder(config, head, Mounting(), Still())
    done = [builder.add(b) for b in series]  # four beams of a quarter turn each: one scan
    assert done[-1] is not None
    np.testing.assert_allclose(done[-1].points_b[:, 0], 10 * own - 0.05, atol=1e-12)
