"""A BlueROV2's own navigation logs (datasets/navlog.py and its readers), on the files the
simulator writes in each format with its writer's known defects, against the simulator's truth:
what each reader recovers (and to what tolerance, given what the format keeps), the corrupt
chunks survived and counted, files told apart by content, the autopilot's velocity taken with
an honest noise, and the round trip: a dive written as .bin + .tlog (or + the A50's JSON) runs
every back end as the same dive read from its directory."""

from __future__ import annotations

import math
import time
import tomllib
import tracemalloc
import warnings
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from sonarslam.datasets.dataset import Dataset
from sonarslam.datasets.dvljson import read_dvl_json
from sonarslam.datasets.errors import DataError, DataWarning
from sonarslam.datasets.mavlink import read_dataflash, read_tlog
from sonarslam.datasets.navlog import (
    AUTOPILOT_VELOCITY_SIGMA_MPS,
    nav_log_kind,
    navigation,
    read_nav_log,
)
from sonarslam.datasets.navrecords import NavLogSettings
from sonarslam.datasets.qgccsv import read_qgc_csv
from sonarslam.datasets.simulator.bluerov import (
    autopilot_velocity,
    write_bluerov_nav,
    write_busy_tlog,
    write_dataflash,
    write_dvl_json,
    write_qgc_csv,
    write_tlog,
)
from sonarslam.datasets.simulator.ping360 import write_ping360_run
from sonarslam.datasets.source import open_dataset
from sonarslam.slam.cli.main import main
from sonarslam.slam.run.run import run_backend

#: QGroundControl stamps a record 5-20 ms after the simulated sample (the writer's latency):
#: a heading turning at the run's rate moves this much in 20 ms, with float32's rounding (deg).
LATENCY_HEADING_TOL_DEG = 1.0
#: The round trip's tolerance: a back end on the .bin and its navigation log against the same
#: back end on the dive's directory, ATE against the truth (issue 41's target).
ROUND_TRIP_REL, ROUND_TRIP_ABS_M = 0.05, 0.05


@pytest.fixture(scope="module")
def layout(ping360_layout: Path) -> Path:
    """The harbour dive in the marina layout (conftest's ``ping360_layout``, read only)."""
    return ping360_layout


def _quiet_open(path: Path, **kw: object) -> Dataset:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DataWarning)
        return open_dataset(path, **kw)  # type: ignore[arg-type]


@pytest.fixture(scope="module")
def direct(layout: Path) -> Dataset:
    return _quiet_open(layout)


def _bin_with(direct: Dataset, layout: Path, folder: Path, nav: str) -> tuple[Path, list[Path]]:
    """The dive as a .bin and its navigation ``nav``, [ping360] nav naming the first file."""
    log = write_ping360_run(direct, folder, layout)
    (folder / "nav.bag").unlink()
    files, navlog = write_bluerov_nav(direct, folder, nav, seed=3)
    toml = (folder / "sonarslam.toml").read_text(encoding="utf-8").split("\n[ping360]")[0]
    toml += f'\n[ping360]\nnav = "{files[0].name}"\n' + navlog
    (folder / "sonarslam.toml").write_text(toml, encoding="utf-8")
    return log, files


def _nearest(t: np.ndarray, t_ref: np.ndarray) -> np.ndarray:
    """The index in ``t`` of the sample nearest each of ``t_ref``."""
    i = np.clip(np.searchsorted(t, t_ref), 1, len(t) - 1)
    return np.where(np.abs(t[i - 1] - t_ref) < np.abs(t[i] - t_ref), i - 1, i)


def test_a_tlog_through_its_corrupt_chunks_gives_the_simulated_streams(
    direct: Dataset, tmp_path: Path
) -> None:
    path = write_tlog(direct, tmp_path / "dive.tlog", np.random.default_rng(7), corrupt_chunks=4)
    with pytest.warns(DataWarning, match=r"4 corrupt chunk\(s\) .* the first at byte offset"):
        log = read_tlog(path)
    assert log.counts["navlog_corrupt_chunks"] == 4
    assert 0 < log.counts["navlog_corrupt_bytes"] < 4 * 300 + 100  # what was overwritten
    # the camera's ATTITUDE (another component) is counted, not mixed into the heading
    assert log.counts["navlog_other_sources"] >= 10
    att, ref = log.attitude, direct.attitude
    assert att is not None and att.t.size >= 0.97 * ref.t.size  # a chunk costs a few records
    k = _nearest(att.t, ref.t + 0.0125)
    same = np.abs(att.t[k] - ref.t - 0.0125) <= 0.0076  # the record of that sample
    assert same.mean() > 0.97
    miss = np.degrees(np.abs(np.angle(np.exp(1j * (att.yaw_rad[k] - ref.yaw_rad)))))[same]
    assert miss.max() < LATENCY_HEADING_TOL_DEG
    np.testing.assert_allclose(
        att.yaw_rate_rad_per_s[k][same], ref.yaw_rate_rad_per_s[same], atol=1e-6
    )
    # the DVL's own deltas: every valid row but those in a chunk, velocities to float32's
    dvl = log.dvl
    assert dvl is not None and dvl.valid.all()
    valid = direct.dvl.valid
    j = _nearest(dvl.t, direct.dvl.t[valid])
    found = np.abs(dvl.t[j] - direct.dvl.t[valid]) < 0.03
    assert found.mean() > 0.95
    np.testing.assert_allclose(dvl.v_mps[j[found]], direct.dvl.v_mps[valid][found], atol=1e-5)
    # the Underwater GPS's fixes: degE7 (1 cm)
    assert log.gps is not None and direct.gps is not None
    g = _nearest(log.gps.t, direct.gps.t)
    ok = np.abs(log.gps.t[g] - direct.gps.t) < 0.03
    np.testing.assert_allclose(log.gps.en_m[g[ok]], direct.gps.en_m[ok], atol=0.02)
    assert "Underwater GPS" in log.gps_source and "VISION_POSITION_DELTA" in log.dvl_source


def test_a_dataflash_log_on_its_gps_clock_with_its_first_ekf_core(
    direct: Dataset, tmp_path: Path
) -> None:
    path = write_dataflash(direct, tmp_path / "00000042.BIN", np.random.default_rng(7))
    with pytest.warns(DataWarning, match="corrupt chunk"):
        log = read_dataflash(path)
    assert log.counts["navlog_corrupt_chunks"] == 3
    assert log.counts["navlog_cut_tail_bytes"] == 0  # the block logger's padding: no fault
    assert any("GPS time" in n for n in log.notes) and any("ArduSub" in n for n in log.notes)
    att, ref = log.attitude, direct.attitude
    assert att is not None
    k = _nearest(att.t, ref.t)
    same = np.abs(att.t[k] - ref.t) < 1e-3  # GPS week ms: the clock to 1 ms
    assert same.mean() > 0.97  # but the messages in the corrupt chunks
    miss = np.degrees(np.abs(np.angle(np.exp(1j * (att.yaw_rad[k] - ref.yaw_rad)))))[same]
    assert miss.max() < 0.006  # centidegrees
    # XKF1 core 0, not core 1 (0.3 m/s off in the writer)
    assert log.autopilot is not None
    t_ap, v_ap = autopilot_velocity(direct)
    a = _nearest(log.autopilot.t, t_ap)
    hit = np.abs(log.autopilot.t[a] - t_ap) < 1e-3
    assert hit.mean() > 0.97
    np.testing.assert_allclose(log.autopilot.v_en_mps[a[hit]], v_ap[hit], atol=1e-5)


def test_the_a50_json_in_each_protocol_gives_its_clock(direct: Dataset, tmp_path: Path) -> None:
    rng = np.random.default_rng(7)
    valid = direct.dvl.valid
    # json_v3: time_of_validity; a cut line dropped and counted
    v3 = write_dvl_json(direct, tmp_path / "v3.json", rng, "json_v3", bad_lines=1)
    with pytest.warns(DataWarning, match=r"1 line\(s\) that are not a whole DVL report"):
        log = read_dvl_json(v3)
    assert log.counts["navlog_bad_lines"] == 1
    assert log.dvl is not None and log.dvl.t.size >= direct.dvl.t.size - 1
    j = _nearest(log.dvl.t, direct.dvl.t)
    same = np.abs(log.dvl.t[j] - direct.dvl.t) < 1e-6
    assert same.sum() >= direct.dvl.t.size - 1  # but the cut line's
    both = same & valid
    np.testing.assert_allclose(log.dvl.v_mps[j][both], direct.dvl.v_mps[both], atol=1e-12)
    # its heading is the A50's gyro: the AHRS's less a constant (no North)
    assert log.attitude is not None and not log.heading_absolute
    k = _nearest(log.attitude.t, direct.attitude.t[::2])
    offset = np.angle(np.exp(1j * (direct.attitude.yaw_rad[::2] - log.attitude.yaw_rad[k])))
    assert np.std(np.unwrap(offset)) < math.radians(0.01)
    # json_v2: no time_of_validity, the running sum anchored on position_local's ts
    v2 = write_dvl_json(direct, tmp_path / "v2.json", rng, "json_v2", bad_lines=0)
    log2 = read_dvl_json(v2)
    assert log2.dvl is not None
    j2 = _nearest(log2.dvl.t, direct.dvl.t)
    # bracketed between the dead-reckoning reports around it (5 Hz here): half their spacing
    assert np.abs(log2.dvl.t[j2] - direct.dvl.t).max() < 0.1
    # json_v1: velocities only, time in ms since the report before: it needs a start ...
    v1 = write_dvl_json(direct, tmp_path / "v1.json", rng, "json_v1", bad_lines=1)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DataWarning)
        with pytest.raises(DataError, match=r"ms since the report before .* \[navlog\] start"):
            read_dvl_json(v1)
        start = NavLogSettings(start=_iso(float(direct.dvl.t[0])))
        log1 = read_dvl_json(v1, start)
    # ... and the lost line's time is patched in: the clock after it does not run early
    assert log1.counts["navlog_clock_patches"] == 1
    assert log1.dvl is not None
    j1 = _nearest(log1.dvl.t, direct.dvl.t)
    miss = np.sort(np.abs(log1.dvl.t[j1] - direct.dvl.t))
    assert miss[-2] < 0.05  # all but the lost report's: the median's difference to its time
    span = direct.dvl.t[-1] - direct.dvl.t[0]
    assert abs((log1.dvl.t[-1] - log1.dvl.t[0]) - span) < 0.05  # unpatched: a report short
    # ... and it has no heading: alone it cannot navigate
    with pytest.raises(DataError, match="json_v1 holds velocities only"):
        navigation([log1], direct.config)


def _iso(t: float) -> str:
    return np.datetime_as_string(np.datetime64(int(round(t * 1e6)), "us"), unit="ms") + "+00:00"


def test_the_qgc_csv_is_a_coarse_navigation_on_local_time(direct: Dataset, tmp_path: Path) -> None:
    path = write_qgc_csv(direct, tmp_path / "2024-05-02 10-31-07 vehicle1.csv", utc_offset_h=2.0)
    log = read_qgc_csv(path, NavLogSettings(utc_offset_h=2.0))
    assert log.attitude is not None and log.autopilot is not None and log.gps is not None
    assert np.allclose(np.diff(log.attitude.t), 1.0)  # a row a second
    ref = np.interp(log.attitude.t, direct.attitude.t, np.unwrap(direct.attitude.yaw_rad))
    miss = np.degrees(np.abs(np.angle(np.exp(1j * (log.attitude.yaw_rad - ref)))))
    assert miss.max() < 0.5 + 1e-6  # whole degrees
    t_ap, v_ap = autopilot_velocity(direct)
    a = np.minimum(np.searchsorted(t_ap, log.autopilot.t), t_ap.size - 1)  # the row's sample
    np.testing.assert_allclose(log.autopilot.v_en_mps, v_ap[a], atol=0.05 + 1e-9)  # 0.1 m/s
    # read in the wrong zone, the rows miss by the offset
    wrong = read_qgc_csv(path)
    assert wrong.attitude is not None
    np.testing.assert_allclose(wrong.attitude.t - log.attitude.t, 7200.0, atol=1e-6)
    assert any("coarse" in n for n in log.notes)


def test_files_are_told_apart_by_content_not_by_name(
    direct: Dataset, layout: Path, tmp_path: Path
) -> None:
    log, files = _bin_with(direct, layout, tmp_path / "a", "dataflash")
    flash = files[0].rename(files[0].with_suffix(".bin"))
    assert nav_log_kind(log) is None  # a Ping Viewer .bin
    assert nav_log_kind(flash) == "dataflash"
    tlog = write_tlog(direct, tmp_path / "x.dat", np.random.default_rng(1), corrupt_chunks=0)
    assert nav_log_kind(tlog) == "tlog"
    assert nav_log_kind(tmp_path / "a" / "sonarslam.toml") is None
    with pytest.raises(DataError, match=r"a navigation log \(ArduSub dataflash .*, not a sonar"):
        open_dataset(flash)
    with pytest.raises(DataError, match="not a navigation log this reads"):
        read_nav_log(tmp_path / "a" / "sonarslam.toml")


def test_info_says_what_a_navigation_log_alone_holds(
    direct: Dataset, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path = write_tlog(direct, tmp_path / "dive.tlog", np.random.default_rng(7), corrupt_chunks=2)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DataWarning)
        assert main(["info", str(path)]) == 0
    out = capsys.readouterr().out
    assert "QGroundControl telemetry log" in out
    assert "ATTITUDE" in out and "Hz" in out and "-> heading" in out
    assert "odometry: VISION_POSITION_DELTA" in out and "ruler: GPS_INPUT" in out
    assert "'corrupt_chunks': 2" in out


def _ate(d: Dataset, backend: str, aligned: bool) -> float:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DataWarning)
        m = run_backend(d, backend).metrics
    return float(m["ate_truth_aligned_mean_m" if aligned else "ate_truth_mean_m"])


@pytest.mark.parametrize(
    ("nav", "backends", "aligned"),
    [
        ("tlog", ("dr", "gps", "ekf", "isam2"), False),
        # the A50's heading has no North (and its log no GPS): a rigid fit onto the truth
        ("dvl_json", ("dr", "ekf", "isam2"), True),
    ],
)
def test_a_dive_as_bin_and_its_log_runs_as_from_its_directory(
    direct: Dataset,
    layout: Path,
    tmp_path: Path,
    nav: str,
    backends: tuple[str, ...],
    aligned: bool,
) -> None:
    log, _ = _bin_with(direct, layout, tmp_path / nav, nav)
    d = _quiet_open(log)
    assert "navigation: odometry" in d.calibration
    for backend in backends:
        ref, got = _ate(direct, backend, aligned), _ate(d, backend, aligned)
        assert abs(got - ref) <= ROUND_TRIP_REL * ref + ROUND_TRIP_ABS_M, (backend, got, ref)


def test_the_autopilot_velocity_is_taken_with_an_honest_noise(
    direct: Dataset, layout: Path, tmp_path: Path
) -> None:
    """Its errors are its filter's, correlated over its time constant: at the DVL's sigma the
    dead reckoning's NEES says it is far more sure than it is; at the floor, less so; and the
    ruler it may have fused is said."""
    log, _ = _bin_with(direct, layout, tmp_path / "ap", "tlog")
    toml = log.parent / "sonarslam.toml"
    toml.write_text(
        toml.read_text(encoding="utf-8") + '\n[navlog]\nodometry = "autopilot"\n',
        encoding="utf-8",
    )
    with pytest.warns(DataWarning) as said:
        d = open_dataset(log)
    text = " ".join(str(w.message) for w in said)
    assert f"raised to {AUTOPILOT_VELOCITY_SIGMA_MPS:g} m/s" in text
    assert "not independent of the ruler" in text
    assert d.config.noise.dvl_sigma_mps == AUTOPILOT_VELOCITY_SIGMA_MPS
    assert d.config.dvl_mounting.yaw_rad == d.config.ahrs_mounting.yaw_rad
    assert "LOCAL_POSITION_NED" in d.calibration
    silent = replace(d, config=replace(d.config, noise=direct.config.noise))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DataWarning)
        nees_silent = run_backend(silent, "dr").metrics["nees_position_mean"]
        nees = run_backend(d, "dr").metrics["nees_position_mean"]
    assert nees < 0.5 * nees_silent, (nees, nees_silent)


def _traced_peak(path: Path) -> int:
    tracemalloc.start()
    try:
        read_tlog(path)
        return tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()


def test_a_tlog_reads_fifty_times_faster_than_real_time_in_flat_memory(tmp_path: Path) -> None:
    """Read at least 50x real time (an hour: benchmarks/navlog_reading.py); the memory grows
    with the streams read (8 bytes a value), not with the file: a minute more of log adds less
    than half its bytes (the servo outputs, two thirds of it, are counted, not kept)."""
    short = write_busy_tlog(tmp_path / "a.tlog", 60.0)
    long = write_busy_tlog(tmp_path / "b.tlog", 120.0)
    began = time.perf_counter()
    log = read_tlog(long)
    wall = time.perf_counter() - began
    assert log.attitude is not None and log.attitude.t.size == 20 * 120
    assert 120.0 / wall >= 50.0, f"{120.0 / wall:.0f}x real time"
    grown = _traced_peak(long) - _traced_peak(short)
    added = long.stat().st_size - short.stat().st_size
    assert grown < 0.5 * added, (grown, added)


def test_a_still_vehicle_in_a_qgc_export_runs_and_is_told_what_the_export_is(
    tmp_path: Path,
) -> None:
    """The simulated pool's vehicle holds still: QGroundControl's export rounds its velocity to
    0.1 m/s, so every row reads (0, 0). Those are readings under the export's resolution, not
    a dropout's fill (a review: every row flagged, `run` refused the dataset, and the warning
    asked the export for a dvl_valid column, which is the navigation CSV's); dead reckoning
    holds still at its start; the warnings name the export and the mounting that replaced the
    DVL's."""
    from sonarslam.datasets.simulator.bluerov import simulate_bluerov
    from sonarslam.slam.eval.truth import truth_trajectory
    from sonarslam.slam.run.sources import start_pose

    log, _ = simulate_bluerov("pool", 0, tmp_path / "rov", "qgc_csv", duration_s=20.0)
    with pytest.warns(DataWarning) as said:
        d = open_dataset(log)
    text = " ".join(str(w.message) for w in said)
    assert "dvl_valid" not in text and "exactly (0, 0)" not in text
    assert "[mounting.dvl] (0 m, 0 m, -90 deg) replaced by the AHRS's (0 m, 0 m, 0 deg)" in text, (
        text
    )
    assert "QGroundControl's CSV export rounds" in text  # the still vehicle's slowness said
    assert d.dvl.valid.all() and not d.dvl.v_mps.any()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DataWarning)
        result = run_backend(d, "dr")
    dr = result.trajectory.poses_wTb
    np.testing.assert_allclose(dr[:, :2] - dr[0, :2], 0.0, atol=1e-9)  # holds still
    truth = truth_trajectory(d).poses_wTb
    _, pose0, _ = start_pose(d)
    miss = float(np.hypot(*(truth[0, :2] - pose0[:2])))  # the first GPS fix's noise
    assert result.metrics["ate_truth_mean_m"] == pytest.approx(miss, abs=1e-6)


def test_ping360_nav_takes_a_list_and_the_json_v1_dive_runs_alone(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """`[ping360] nav` takes a list of files as `--nav` may be repeated: the A50's json_v1
    (velocities only) and the autopilot's ATTITUDE-only .tlog (the heading), both written by
    `simulate --bluerov dvl_json_v1`, so the .bin runs alone (a review: `nav = "dvl.json"`
    only, "no heading in dvl.json", and a list refused as "must be a string"); a list that is
    not of file names is named; `calibrate --write` keeps the list, relative to the new file."""
    from sonarslam.datasets.ping360 import ping360_table

    folder = tmp_path / "v1"
    assert (
        main(
            ["simulate", "pool", "--duration", "20", "--bluerov", "dvl_json_v1"]
            + ["--out", str(folder)]
        )
        == 0
    )
    said = capsys.readouterr().out
    log = next(folder.glob("*.bin"))
    assert f"run it: sonarslam run {log}\n" in said  # no --nav needed
    toml = folder / "sonarslam.toml"
    assert 'nav = ["dvl.json", "attitude.tlog"]' in toml.read_text()
    d = _quiet_open(log)
    assert "odometry" in d.calibration and "of dvl.json" in d.calibration
    assert "of attitude.tlog" in d.calibration  # the heading
    kept = tomllib.loads(ping360_table(log, folder / "new.toml"))["ping360"]["nav"]
    assert kept == ["dvl.json", "attitude.tlog"]
    text = toml.read_text().replace('"attitude.tlog"', "3")
    toml.write_text(text)
    with pytest.raises(DataError, match=r"\[ping360\] nav must be a file name or a list of"):
        _quiet_open(log)
