"""A Ping Viewer log as the field writes it (issue 41): the simulator's pool written as a
``.bin`` alone, its records split mid-message, its name and stamps in Persian digits, its range
changed three times in the first seconds (2 -> 15 -> 60 m, then the pool's 6 m), every 50th
beam cut short on the link, and no navigation; read back and checked against the simulator's
truth: the beams its bytes hold, the segments, the lines and their covariances from the still
head, and each segment's echoes on the true walls."""

from __future__ import annotations

import json
import math
import warnings
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from sonarslam.datasets.dataset import Dataset
from sonarslam.datasets.errors import DataWarning
from sonarslam.datasets.records import BeamSeries
from sonarslam.datasets.simulator.ping360 import PERSIAN_ZERO, Ping360Defects, simulate_ping360
from sonarslam.datasets.source import open_dataset
from sonarslam.features.extractor import LineExtractor
from sonarslam.features.geometry import line_difference, line_world_to_frame
from sonarslam.features.line import LineFeature
from sonarslam.features.pose_source import PoseSource
from sonarslam.features.projection import project_beams
from sonarslam.slam.cli.main import main
from sonarslam.slam.eval.truth import truth_trajectory, truth_walls, wall_lines_world
from sonarslam.slam.run.presets import extractor_config, preset_for
from sonarslam.slam.run.sources import dead_reckoning_trajectory

DEFECTS = Ping360Defects(
    zero_digit=PERSIAN_ZERO,
    first_ranges_m=(2.0, 15.0, 60.0),
    first_range_s=12.0,
    lose_every=50,
    nav=False,
)


@pytest.fixture(scope="module")
def field_log(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """60 s of the pool (seed 4) written with :data:`DEFECTS`."""
    return simulate_ping360("pool", 4, tmp_path_factory.mktemp("field"), 60.0, defects=DEFECTS)


@pytest.fixture(scope="module")
def still(field_log: Path) -> Dataset:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DataWarning)
        return open_dataset(field_log)


def _truth(field_log: Path) -> dict:  # type: ignore[type-arg]
    return json.loads((field_log.parent / "truth.json").read_text())["ping360_log"]  # type: ignore[no-any-return]


def test_every_beam_its_bytes_hold_is_read_in_its_segment(
    field_log: Path, still: Dataset, capsys: pytest.CaptureFixture[str]
) -> None:
    truth = _truth(field_log)
    assert field_log.name.startswith("۲۰۲۳") and still.still
    lost = truth["lost_beams"]
    whole = truth["beams"] - len(lost)  # the beams whose bytes all arrived
    assert len(still.beams) == whole >= 0.97 * truth["beams"]
    assert still.report.counts["ping360_cut_messages"] == len(lost) == 18
    assert still.report.counts["ping360_stray_bytes"] == 0
    # the segments: the truth's ranges, each less the beams lost in it
    first = np.cumsum([0] + [s["beams"] for s in truth["segments"]])
    got = [(g.beams, g.n_bins, g.bin_size_m) for g in still.segments]
    want = [
        (s["beams"] - sum(a <= k < b for k in lost), s["n_bins"], s["bin_size_m"])
        for s, a, b in zip(truth["segments"], first[:-1], first[1:], strict=True)
    ]
    assert got == want and len(got) == 4
    assert [round(g.range_m) for g in still.segments] == [2, 15, 60, 6]
    assert still.config.sonar.n_bins == 1200 and still.config.sonar.bin_size_m == got[2][2]
    assert main(["info", str(field_log)]) == 0
    said = capsys.readouterr().out
    assert "4 segments" in said and "a still head" in said
    assert "3: 24.017 to 35.990 s, 173 beams of 1200 samples of 49.99 mm (range 59.98 m)" in said


def _lines(d: Dataset, poses: PoseSource) -> list[LineFeature]:
    extractor = LineExtractor(
        extractor_config(preset_for(d.beams)), d.config.sonar, d.config.sonar_mounting, poses
    )
    lines = [line for beam in d.beams for line in extractor.add(beam)]
    return lines + extractor.flush()


def test_the_still_heads_lines_are_the_truths_and_on_the_true_walls(still: Dataset) -> None:
    """At the true pose (--start), the still head gives the lines and covariances the truth's
    poses give, bit for bit; every line lies on a true wall within 6 cm and 10 deg, consistent
    with its covariance; each segment has lines of its own."""
    truth = truth_trajectory(still)
    x, y, yaw = truth.poses_wTb[0]
    assert np.ptp(truth.poses_wTb, axis=0).max() == 0.0  # the pool's head does not move
    head = dead_reckoning_trajectory(replace(still, start_enu=(x, y, yaw)))
    lines, reference = _lines(still, head), _lines(still, truth)
    assert len(lines) == len(reference) >= 15
    for a, b in zip(lines, reference, strict=True):
        assert (a.t, a.rho_m, a.theta_rad) == (b.t, b.rho_m, b.theta_rad)
        np.testing.assert_array_equal(a.cov, b.cov)
    walls = wall_lines_world(truth_walls(still))
    nees = []
    for line in lines:
        misses = [
            line_difference([line.rho_m, line.theta_rad], line_world_to_frame(w, line.wTr)[0])[0]
            for w in walls
        ]
        nu = min(misses, key=lambda m: abs(m[0]) + abs(m[1]))
        assert abs(nu[0]) < 0.06 and abs(nu[1]) < math.radians(10.0), (line.t, nu)
        nees.append(float(nu @ np.linalg.solve(line.cov, nu)))
    assert np.median(nees) < 1.39  # chi2(2)'s median: the covariances are not too small
    # the first vote (a full sector, 200 beams of 1 gradian) falls in the 15 m segment and
    # rests on the 2 m segment's beams; then lines in each segment
    segment_of = [sum(line.t >= g.t0_s for g in still.segments) for line in lines]
    assert segment_of[0] == 2 and set(segment_of) == {2, 3, 4}


def test_each_segment_is_placed_by_its_own_bin_size(still: Dataset) -> None:
    """The echoes of each segment, projected at the true pose, lie on the true walls (90 % of
    the bins beyond the ringing within 5 cm); read with the head's bin size (the 60 m
    segment's) the other segments' would not."""
    truth = truth_trajectory(still)
    walls = wall_lines_world(truth_walls(still))
    normals = np.stack([np.cos(walls[:, 1]), np.sin(walls[:, 1])])

    def on_walls(beams: BeamSeries) -> float:
        points, _ = project_beams(
            beams, still.config.sonar, still.config.sonar_mounting, truth, 150
        )
        far = np.linalg.norm(points - truth.poses_wTb[0, :2], axis=1) > 0.6
        miss = np.min(np.abs(points[far] @ normals - walls[:, 0]), axis=1)
        return float(np.mean(miss < 0.05))

    for g in still.segments:
        beams = still.beams.between(g.t0_s, g.t1_s)
        assert beams.bin_size_m is not None and np.all(beams.bin_size_m == g.bin_size_m)
        assert on_walls(beams) > 0.9, g
        if g.bin_size_m != still.config.sonar.bin_size_m:
            one = BeamSeries(beams.t_s, beams.transducer_angle_rad, beams.intensities)
            assert on_walls(one) < 0.1, g


def test_plot_scans_and_a_dead_reckoning_run_take_the_log_alone(
    field_log: Path, still: Dataset, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    x, y, yaw = (float(v) for v in truth_trajectory(still).poses_wTb[0])
    start = f"{x!r},{y!r},{math.degrees(yaw)!r}"
    picture = tmp_path / "scans.png"
    assert main(["plot-scans", str(field_log), "--start", start, "--out", str(picture)]) == 0
    assert picture.stat().st_size > 10_000
    out = tmp_path / "dr"
    assert main(["run", str(field_log), "--start", start, "--out", str(out), "--quiet"]) == 0
    assert "start pose: no navigation: a still head at" in capsys.readouterr().out
    m = json.loads((out / "metrics.json").read_text())
    assert m["evaluation"] == "truth; a still head (no navigation)"
    assert m["ate_truth_max_m"] < 1e-6


def test_simulate_writes_the_field_defects_it_is_asked_for(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "sim"
    args = ["simulate", "pool", "--duration", "8", "--ping360", "--out", str(out)]
    defects = ["--no-nav", "--persian-digits", "--first-ranges", "2,15"]
    assert main([*args, *defects]) == 0
    assert "without navigation (a still head)" in capsys.readouterr().out
    (log,) = out.glob("*.bin")
    assert log.name[0] == "۲" and not (out / "nav.bag").exists()
    assert "[ping360]\nspeed_of_sound_mps" in (out / "sonarslam.toml").read_text()
    with pytest.warns(DataWarning, match="still head"):
        d = open_dataset(log)
    assert [round(g.range_m) for g in d.segments] == [2, 15, 6]
    assert main(["simulate", "pool", "--no-nav", "--out", str(tmp_path / "x")]) == 2
    assert "--no-nav: a Ping360 log's defect: give --ping360 too" in capsys.readouterr().err


def test_span_takes_a_segment_and_its_head(field_log: Path, still: Dataset) -> None:
    """--span after the setup seconds: the pool's own 6 m segment alone, and the head its own
    (500 bins of 12 mm), not the 60 m segment's the whole log's head has."""
    t0 = still.nav_span_s[0]
    fourth = still.segments[3]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DataWarning)
        part = open_dataset(field_log, span_s=(fourth.t0_s - t0, 60.0))
    assert part.still and [g.beams for g in part.segments] == [fourth.beams]
    assert (part.config.sonar.n_bins, part.config.sonar.bin_size_m) == (500, 0.012)
    assert part.beams.intensities.shape == (fourth.beams, 500) and part.beams.bin_size_m is None
    assert part.nav_span_s == (fourth.t0_s, fourth.t1_s)


def test_a_log_of_segments_is_not_written_as_a_bag_of_one_range(
    still: Dataset, tmp_path: Path
) -> None:
    from sonarslam.datasets.rosbag import write_bag

    with pytest.raises(ValueError, match=r"several bin sizes \(segments\) cannot be written"):
        write_bag(still, tmp_path / "x.bag", "ros1")


def test_a_wrong_start_shows_against_the_truth_as_it_is(still: Dataset) -> None:
    """A still head's pose is the one given (--start): against the truth as truth.json has it
    (the simulator's world frame, not moved onto the start), a wrong start's position and
    heading errors are the distances to the true pose (a review: ATE 0.00 m for any start, the
    heading never compared), and the true start's are zero."""
    from sonarslam.slam.run.metrics import trajectory_figures
    from sonarslam.slam.run.run import summary_line

    rows = json.loads((Path(still.root).parent / "truth.json").read_text())["body_poses"]["rows"]
    x, y, yaw = rows[0][1:]
    truth = truth_trajectory(still)
    np.testing.assert_allclose(truth.poses_wTb[0], [x, y, yaw], atol=1e-12)
    wrong = (5.0, 5.0, math.radians(90.0))
    head = dead_reckoning_trajectory(replace(still, start_enu=wrong))
    f = trajectory_figures(still, head, "")
    assert f.ate_truth is not None and f.heading_truth is not None
    assert f.ate_truth.ate_mean_m == pytest.approx(math.hypot(5.0 - x, 5.0 - y), abs=1e-9)
    miss_deg = abs(math.degrees(math.remainder(wrong[2] - yaw, math.tau)))
    assert miss_deg > 90.0  # the pool's head looks about -170 deg
    assert f.heading_truth.mean_deg == pytest.approx(miss_deg, abs=1e-9)
    m = {"backend": "dr", "evaluation": "truth", "data_s": 1.0, "wall_s": 1.0}
    m.update(realtime_factor=1.0, **f.span_json())
    assert f"heading mean {miss_deg:.1f} deg" in summary_line(m)
    right = dead_reckoning_trajectory(replace(still, start_enu=(x, y, yaw)))
    f = trajectory_figures(still, right, "")
    assert f.ate_truth is not None and f.ate_truth.ate_max_m < 1e-9
    assert f.heading_truth is not None and f.heading_truth.max_deg < 1e-9


def test_a_span_without_navigation_counts_from_the_first_beam(still: Dataset) -> None:
    """Without navigation --span counts from the first beam, and its error says so (a review:
    "s from the start of the navigation" of a log that has none)."""
    from sonarslam.datasets.dataset import dataset_span
    from sonarslam.datasets.errors import DataError

    assert still.nav_span_s[0] == pytest.approx(float(still.beams.t_s[0]), abs=1e-9)
    with pytest.raises(DataError, match=r"--span 100,110 \(s from the first beam, the log"):
        dataset_span(still, (100.0, 110.0))
