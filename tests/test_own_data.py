"""Bring your own data: a calibration that is never silently the marina's, runs without GPS
(issue 30, items 3 and 4)."""

from __future__ import annotations

import json
import math
import shutil
import warnings
from collections.abc import Callable
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from sonarslam.datasets.arrays import dataset_from_arrays
from sonarslam.datasets.config import MARINA_CONFIG, DatasetConfig, load_dataset_config
from sonarslam.datasets.errors import DataError, DataWarning
from sonarslam.datasets.geodesy import local_en_to_geodetic
from sonarslam.datasets.source import NEUTRAL_CALIBRATION, Dataset, is_marina, open_dataset
from sonarslam.slam.cli.main import main
from sonarslam.slam.io.trajectory import read_tum
from sonarslam.slam.model.motion import body_yaw
from sonarslam.slam.run.sources import dead_reckoning_trajectory, start_pose


@pytest.fixture(scope="module")
def harbour(simulated: Callable[..., Path]) -> Path:
    return simulated("harbour", 2, 300.0)


def _copy(src: Path, dst: Path, *drop: str) -> Path:
    """``src`` copied to ``dst`` without the files whose names end with one of ``drop``."""
    dst.mkdir()
    for f in src.iterdir():
        if not any(f.name.endswith(d) for d in drop):
            shutil.copy(f, dst / f.name)
    return dst


def test_a_run_without_toml_is_neutral_not_the_marina(harbour: Path, tmp_path: Path) -> None:
    src = _copy(harbour, tmp_path / "copy", "sonarslam.toml")
    with pytest.warns(DataWarning, match="neutral: no sonarslam.toml"):
        d = open_dataset(src)
    assert d.calibration == NEUTRAL_CALIBRATION
    assert not is_marina(src)
    # the head comes from the SETUP log, everything else is DatasetConfig's neutral defaults
    assert replace(d.config, sonar=DatasetConfig().sonar) == DatasetConfig()
    assert d.config.ahrs_mounting != MARINA_CONFIG.ahrs_mounting
    assert d.config.sonar_time_offset_s == 0.0
    with_toml = open_dataset(harbour)
    assert with_toml.calibration == str(harbour / "sonarslam.toml")


def test_marina_logs_are_recognised_by_their_name(tmp_path: Path) -> None:
    (tmp_path / "logs").mkdir()
    assert not is_marina(tmp_path)
    (tmp_path / "logs" / "_040825_1735_DVL.log").write_text("")
    assert is_marina(tmp_path)
    other = tmp_path / "other"
    (other / "keyframes").mkdir(parents=True)
    (other / "keyframes" / "keyFrameTimeStamps.csv").write_text("")
    assert is_marina(other)


def test_the_marina_keeps_its_calibration(marina: Dataset) -> None:
    assert marina.calibration.startswith("marina calibration")
    assert marina.config.sonar_mounting == MARINA_CONFIG.sonar_mounting


def test_run_prints_and_records_the_neutral_calibration_and_calibrate_writes_one(
    harbour: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    src = _copy(harbour, tmp_path / "copy", "sonarslam.toml")
    assert main(["run", str(src), "--out", str(tmp_path / "run"), "--quiet"]) == 0
    out = capsys.readouterr().out
    assert f"calibration: {NEUTRAL_CALIBRATION}" in out
    metrics = json.loads((tmp_path / "run" / "metrics.json").read_text())
    assert metrics["calibration"] == NEUTRAL_CALIBRATION
    written = src / "sonarslam.toml"
    # --ahrs is the quickest calibration; the sonar yaw (the default) writes the same way
    assert main(["calibrate", str(src), "--ahrs", "--write", str(written), "--quiet"]) == 0
    out = capsys.readouterr().out
    found = float(out.split("(GPS-free): ")[1].split(" deg")[0])
    cfg = load_dataset_config(written)
    assert math.degrees(cfg.ahrs_mounting.yaw_rad) == pytest.approx(found, abs=0.005)
    # every other key is what the run had: the neutral calibration, now written down
    neutral = DatasetConfig().ahrs_mounting
    assert replace(cfg, ahrs_mounting=neutral) == replace(
        open_dataset(src).config, ahrs_mounting=neutral
    )
    assert open_dataset(src).calibration == str(written)


def test_a_run_without_gps_starts_at_the_origin_and_says_what_it_measures(
    harbour: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    src = _copy(harbour, tmp_path / "nogps", "_DGPS.log")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DataWarning)
        d = open_dataset(src)
        full = open_dataset(harbour)
    assert d.gps is None
    t0, pose0, _ = start_pose(d)
    assert t0 == d.nav_span_s[0]
    assert pose0[:2].tolist() == [0.0, 0.0]
    # the heading is the AHRS's through its mounting, as with GPS (there at the first fix)
    yaw_a = np.interp(t0, d.attitude.t, np.unwrap(d.attitude.yaw_rad))
    assert pose0[2] == pytest.approx(body_yaw(yaw_a, d.config.ahrs_mounting, (0.0, 0.0)), abs=1e-12)
    t_gps, pose_gps, _ = start_pose(full)
    assert t_gps > t0 and dead_reckoning_trajectory(full).poses_wTb[0, 2] == pose_gps[2]
    assert (
        main(["run", str(src), "--backend", "ekf", "--out", str(tmp_path / "ekf"), "--quiet"]) == 0
    )
    out = capsys.readouterr().out
    assert "start pose: no GPS: the origin" in out and "evaluation: truth and loops (no GPS)" in out
    m = json.loads((tmp_path / "ekf" / "metrics.json").read_text())
    assert "ate_mean_m" not in m and "gps_uncovered_s" not in m
    assert not (tmp_path / "ekf" / "gps.tum").exists()
    assert m["map_entropy_nats"] > 0
    # the truth is moved into the run's frame (origin at the start): the harbour's EKF stays
    # within its usual metre of it (with GPS: 1.06 m mean on this run)
    assert m["ate_truth_mean_m"] < 2.0 and m["ate_truth_aligned_mean_m"] < 0.5
    # without the truth either: the map's entropy and the pictures only
    bare = _copy(src, tmp_path / "bare", "truth.json")
    assert main(["run", str(bare), "--out", str(tmp_path / "dr"), "--quiet"]) == 0
    out = capsys.readouterr().out
    assert "no GPS: no ATE; the loop-closure error (loop_*), the map's entropy" in out
    assert {p.name for p in (tmp_path / "dr").iterdir()} >= {"dr.tum", "report.png", "metrics.json"}
    # report takes it, with the EKF run, in its section of runs without GPS
    assert (
        main(
            ["report", str(tmp_path / "dr"), str(tmp_path / "ekf"), "--out", str(tmp_path / "rep")]
        )
        == 0
    )
    out = capsys.readouterr().out
    assert "dr [dr, bare]: no GPS; loops: 0 stated" in out and "ekf [ekf, nogps]: no GPS" in out
    md = (tmp_path / "rep" / "report.md").read_text()
    assert "## Runs without GPS" in md and (tmp_path / "rep" / "loops_bare.png").is_file()


def test_start_pose_given_and_extract_and_calibrate_without_gps(
    harbour: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    src = _copy(harbour, tmp_path / "nogps", "_DGPS.log")
    run = tmp_path / "dr"
    assert main(["run", str(src), "--out", str(run), "--start", "10,-20", "--quiet"]) == 0
    first = read_tum(run / "dr.tum").poses_wTb[0]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DataWarning)
        yaw = start_pose(open_dataset(src))[1][2]
    np.testing.assert_allclose(first, [10.0, -20.0, yaw], atol=1e-9)
    m = json.loads((run / "metrics.json").read_text())
    assert m["start_pose"].startswith("given (--start 10,-20)")
    # a heading given must agree with the AHRS's (within 3 sigma), else one line says why
    agree = f"10,-20,{math.degrees(yaw) + 1.0:.3f}"
    assert main(["run", str(src), "--out", str(tmp_path / "a"), "--start", agree, "--quiet"]) == 0
    wrong = f"10,-20,{math.degrees(yaw) + 90.0:.3f}"
    assert main(["run", str(src), "--out", str(tmp_path / "w"), "--start", wrong, "--quiet"]) == 1
    assert "differs from the AHRS's" in capsys.readouterr().err
    assert main(["extract", str(src), "--out", str(tmp_path / "x"), "--quiet"]) == 1
    assert "no GPS" in capsys.readouterr().err
    args = ["extract", str(src), "--poses", "dr", "--out", str(tmp_path / "x"), "--quiet"]
    assert main(args) == 0
    assert json.loads((tmp_path / "x" / "extract.json").read_text())["features"] > 0
    assert main(["calibrate", str(src), "--ahrs", "--quiet"]) == 0
    assert "AHRS mounting yaw from the DVL compass" in capsys.readouterr().out
    with pytest.raises(SystemExit, match="2"):
        main(["run", str(src), "--out", str(tmp_path / "y"), "--start", "1,2,3,4"])
    assert "must be X,Y or X,Y,YAW" in capsys.readouterr().err


def _arrays_of(d: Dataset) -> dict[str, object]:
    """The keyword arguments of dataset_from_arrays that rebuild ``d`` (before its gates)."""
    gps = d.gps
    assert gps is not None
    lat, lon = local_en_to_geodetic(gps.en_m[:, 0], gps.en_m[:, 1], *gps.origin_lat_lon_deg)
    beams = d.beams.shifted(-d.config.sonar_time_offset_s)
    return {
        "beam_t_s": beams.t_s,
        "beam_angle_rad": beams.transducer_angle_rad,
        "beam_intensities": beams.intensities,
        "dvl_t_s": d.dvl.t,
        "dvl_v_mps": d.dvl.v_mps,
        "dvl_valid": d.dvl.valid,
        "ahrs_t_s": d.attitude.t,
        "ahrs_yaw_rad": d.attitude.yaw_rad,
        "ahrs_yaw_rate_rad_per_s": d.attitude.yaw_rate_rad_per_s,
        "gps_t_s": gps.t,
        "gps_lat_lon_deg": np.column_stack([lat, lon]),
    }


def test_a_dataset_from_arrays_is_the_directorys_and_is_gated(
    opened: Callable[..., Dataset],
) -> None:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DataWarning)
        d = opened("harbour", 2, 300.0)  # the module's harbour, as open_dataset read it
        a = dataset_from_arrays(d.config, name="h", **_arrays_of(d))  # type: ignore[arg-type]
    assert a.calibration.startswith("given with the arrays")
    np.testing.assert_array_equal(a.beams.intensities, d.beams.intensities)
    np.testing.assert_allclose(a.beams.t_s, d.beams.t_s, rtol=0, atol=1e-6)
    assert a.gps is not None and d.gps is not None
    np.testing.assert_allclose(a.gps.en_m, d.gps.en_m, rtol=0, atol=1e-6)
    dr_a, dr_d = dead_reckoning_trajectory(a), dead_reckoning_trajectory(d)
    np.testing.assert_allclose(dr_a.poses_wTb, dr_d.poses_wTb, rtol=0, atol=1e-6)
    # the gates run: a stamp repeated, a DVL spike, a GPS outlier are counted as from a file
    kw = _arrays_of(d)
    t = np.array(kw["ahrs_t_s"])
    t[10] = t[9]
    v = np.array(kw["dvl_v_mps"])
    v[20] = [9.0, 0.0]
    ll = np.array(kw["gps_lat_lon_deg"])
    ll[50, 0] += 0.01  # ~1.1 km north
    kw.update(ahrs_t_s=t, dvl_v_mps=v, gps_lat_lon_deg=ll)
    with pytest.warns(DataWarning, match="repeating a stamp"):
        g = dataset_from_arrays(d.config, **kw)  # type: ignore[arg-type]
    assert g.report.counts["ahrs_repeated_stamps"] == 1
    assert g.report.counts["dvl_speed_spikes"] == 1
    assert g.report.counts["gps_outliers"] == 1


@pytest.mark.parametrize(
    ("change", "message"),
    [
        ({"dvl_t_s": "backwards"}, r"<arrays>: dvl_t_s: row 5 \(.*\) is earlier than row 4"),
        ({"ahrs_yaw_rad": "nan"}, r"ahrs_yaw_rad: row 7 is not finite"),
        ({"beam_intensities": "bins"}, r"beam_intensities must have shape \(\d+, 500\)"),
        (
            {"beam_intensities": "floats"},
            r"beam_intensities must be uint8 echo strengths 0-255, got float64 \(floats scaled 0-1",
        ),
        ({"gps_lat_lon_deg": None}, "gps_t_s and gps_lat_lon_deg go together"),
        (
            {"ahrs_yaw_rad": "degrees"},
            r"<arrays>: ahrs_yaw_rad: row 0 \(-?\d+\.?\d*\) is beyond 2 pi rad .*degrees\?",
        ),
        ({"beam_angle_rad": "degrees"}, r"beam_angle_rad: row \d+ \(.*\) is beyond 2 pi rad"),
        ({"ahrs_yaw_rad": "wrap360"}, r"ahrs_yaw_rad: row 8 \(.*\) is more than 3 pi rad"),
    ],
)
def test_bad_arrays_are_named(
    opened: Callable[..., Dataset], change: dict[str, object], message: str
) -> None:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DataWarning)
        d = opened("harbour", 2, 300.0)  # the module's harbour, as open_dataset read it
    kw = _arrays_of(d)
    key, how = next(iter(change.items()))
    value = None if how is None else np.array(kw[key])
    if how == "backwards":
        assert value is not None
        value[5] = value[4] - 1.0
    elif how == "nan":
        assert value is not None
        value[7] = np.nan
    elif how == "bins":
        assert value is not None
        value = value[:, :100]
    elif how == "degrees":
        value = np.degrees(value)
    elif how == "floats":  # 0-1 instead of 0-255
        value = np.asarray(value) / 255.0
    elif how == "wrap360":  # degrees wrapping at 360 from a start near East
        assert value is not None
        value[:8], value[8:] = 1.0, 359.0
    kw[key] = value
    with pytest.raises(DataError, match=message):
        dataset_from_arrays(d.config, **kw)  # type: ignore[arg-type]


def test_an_unwrapped_yaw_in_radians_is_taken_as_the_wrapped_one(
    opened: Callable[..., Dataset],
) -> None:
    """The check for degrees leaves alone an unwrapped series (np.unwrap, turns counted on):
    its dead reckoning is the wrapped series' own."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DataWarning)
        d = opened("harbour", 2, 300.0)
        kw = _arrays_of(d)
        yaw = np.asarray(kw["ahrs_yaw_rad"])
        turned = np.unwrap(yaw) + 2.0 * np.pi * np.linspace(0.0, 3.0, yaw.size).round()
        assert np.abs(turned).max() > 4.0 * np.pi  # beyond two turns, never by a 3 pi step
        a = dataset_from_arrays(d.config, **kw)  # type: ignore[arg-type]
        b = dataset_from_arrays(d.config, **{**kw, "ahrs_yaw_rad": turned})  # type: ignore[arg-type]
    dr_a, dr_b = dead_reckoning_trajectory(a), dead_reckoning_trajectory(b)
    np.testing.assert_allclose(dr_b.poses_wTb[:, :2], dr_a.poses_wTb[:, :2], rtol=0, atol=1e-6)
    yaw_diff = np.angle(np.exp(1j * (dr_b.poses_wTb[:, 2] - dr_a.poses_wTb[:, 2])))
    assert np.abs(yaw_diff).max() < 1e-9
