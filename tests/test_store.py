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
