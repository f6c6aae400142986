"""Readers: exact counts of the real marina logs, the raw-log round trip, and every bad input."""

from __future__ import annotations

import itertools
import re
import shutil
import warnings
from pathlib import Path

import numpy as np
import pytest

from sonarslam.datasets.config import GateConfig, load_dataset_config
from sonarslam.datasets.errors import DataError, DataWarning
from sonarslam.datasets.gates import GPS_NEIGHBOUR_WINDOW_S
from sonarslam.datasets.gates import _outliers as _gps_outliers
from sonarslam.datasets.geodesy import (
    ddmm_to_degrees,
    degrees_to_ddmm,
    geodetic_to_local_en,
    local_en_to_geodetic,
)
from sonarslam.datasets.islog import read_is_log, write_is_log
from sonarslam.datasets.keyframes import read_pcd_xy
from sonarslam.datasets.logfile import (
    NUMBER,
    Table,
    _fast_table,
    _numbers,
    data_lines,
    parse_table,
    read_table,
)
from sonarslam.datasets.marina import read_dgps, read_dvl, read_is_timestamps, read_mti
from sonarslam.datasets.source import open_dataset
from sonarslam.sonar.beam import SonarBeam
from tests.conftest import marina_root, needs_marina

DVL_ROW = "1093455407.147\t\t2007 3 16 13 0 56 38.20 -47.00 1.80 1 6.10 -4.90 2.80 1 1.84 1.88 1.86 143.00 142.00 149.00 100 207.70 -0.50 1.60 14.27 1488.00 12.80 0.50 1.50 0.08 -0.25"
MTI_ROW = "{t}\t\t0.5\t-2.5\t-126.276\t\t0.01\t-0.006\t0.005\t\t-0.42\t-0.07\t-9.77"


def write_lines(path: Path, lines: list[str]) -> Path:
    path.write_text("% header\r\n" + "\r\n".join(lines) + "\r\n", encoding="latin-1")
    return path


# --- the real marina ---------------------------------------------------------------------------


@needs_marina
def test_marina_counts(marina):
    assert marina.dvl.t.size == 5045
    assert marina.attitude.t.size == 33457
    assert marina.gps is not None and marina.gps.t.size == 3342
    stamps = read_is_timestamps(next((marina_root() / "logs").glob("*_IS_timestamps.log")))
    assert stamps.size == 46259
    assert len(marina.beams) == 230 * 200
    # each scan starts at angle 0 and turns toward decreasing angle (datasets/keyframes.py)
    angles = np.array([b.transducer_angle_rad for b in marina.beams[:200]])
    assert angles[0] == 0.0
    assert np.allclose(angles[1:], np.deg2rad(1.8) * np.arange(199, 0, -1), atol=1e-12)
    assert all(b.thresholded for b in marina.beams[:5])
    # every beam time is a row of IS_timestamps (plus the calibrated clock offset), in order
    t = np.array([b.t for b in marina.beams]) - marina.config.sonar_time_offset_s
    assert np.all(np.diff(t) > 0)
    assert np.abs(stamps[np.searchsorted(stamps, t - 1e-6)] - t).max() < 1e-6


@needs_marina
def test_marina_frames(marina):
    # origin at the first DGPS fix; the run spans ~120 m east and ~240 m south
    assert np.allclose(marina.gps.en_m[0], 0.0, atol=1e-6)
    assert 100 < np.ptp(marina.gps.en_m[:, 0]) < 140 and 220 < np.ptp(marina.gps.en_m[:, 1]) < 260
    # MTi heading -126.276 deg (clockwise from north) is yaw 216.276 deg CCW from east
    assert abs(marina.attitude.yaw_rad[0] - np.deg2rad(216.276 - 360.0)) < 1e-9
    # 84 DVL rows without bottom lock, kept and flagged
    assert int((~marina.dvl.valid).sum()) == 84


# --- geodesy -----------------------------------------------------------------------------------


def test_ddmm_round_trip_and_local_frame():
    assert abs(ddmm_to_degrees(4212.225) - (42 + 12.225 / 60)) < 1e-12
    assert abs(degrees_to_ddmm(ddmm_to_degrees(306.2832)) - 306.2832) < 1e-9
    lat0, lon0 = 42.20375, 3.10472
    lat, lon = local_en_to_geodetic(np.array([10.0, -50.0]), np.array([100.0, 3.0]), lat0, lon0)
    en = geodetic_to_local_en(lat, lon, lat0, lon0)
    assert np.allclose(en, [[10.0, 100.0], [-50.0, 3.0]], atol=1e-6)
    # one minute of latitude is ~1852 m
    en = geodetic_to_local_en(np.array([lat0 + 1 / 60]), np.array([lon0]), lat0, lon0)
    assert abs(en[0, 1] - 1852.0) < 10.0


# --- raw IS log --------------------------------------------------------------------------------


def test_is_log_round_trip(tmp_path):
    rng = np.random.default_rng(3)
    beams = [
        SonarBeam(
            1.7e9 + 0.068 * i,
            float(np.deg2rad(1.8) * i % (2 * np.pi)),
            rng.integers(0, 256, 500).astype(np.uint8),
        )
        for i in range(50)
    ]
    path = tmp_path / "x_IS.log"
    assert write_is_log(path, beams) == 50
    lines = path.read_text().splitlines()
    assert all(line.startswith("%") for line in lines[:7]) and not lines[7].startswith("%")
    back = read_is_log(path)
    assert len(back) == 50
    for a, b in zip(beams, back, strict=True):
        assert abs(a.t - b.t) < 5e-4
        assert abs(a.transducer_angle_rad - b.transducer_angle_rad) < 1e-6
        assert np.array_equal(a.intensities, b.intensities)


def test_is_log_truncated_last_row_is_skipped_with_warning(tmp_path):
    beams = [SonarBeam(10.0 + i, 0.1 * i, np.full(20, i, np.uint8)) for i in range(5)]
    path = tmp_path / "t_IS.log"
    write_is_log(path, beams)
    text = path.read_text()
    path.write_text(text[: text.rstrip().rfind(" ")])  # cut the last row mid-way
    with pytest.warns(DataWarning, match=r"skipped 1 row.*lines 12"):
        back = read_is_log(path)
    assert len(back) == 4


def test_is_log_intensity_out_of_range(tmp_path):
    path = write_lines(tmp_path / "b_IS.log", ["1.0 0 0.0 1 2 3", "2.0 0 0.1 1 300 3"])
    with pytest.raises(DataError, match=r"b_IS.log:3: intensity not a whole number in 0-255"):
        read_is_log(path)


# --- bad input, one case each ------------------------------------------------------------------


def test_missing_file_names_it(tmp_path):
    with pytest.raises(DataError, match=r"nope_DVL.log: file not found"):
        read_dvl(tmp_path / "nope_DVL.log")


def test_non_numeric_field_names_file_and_line(tmp_path):
    path = write_lines(
        tmp_path / "a_MTi.log",
        [MTI_ROW.format(t=1.0), MTI_ROW.format(t=2.0).replace("-2.5", "x2.5")],
    )
    with pytest.raises(DataError, match=r"a_MTi.log:3: non-numeric field 'x2.5'"):
        read_mti(path)


def test_time_going_backwards_names_file_and_line(tmp_path):
    path = write_lines(tmp_path / "a_MTi.log", [MTI_ROW.format(t=t) for t in (1.0, 2.0, 1.5, 3.0)])
    with pytest.raises(DataError, match=r"a_MTi.log:4: time goes backwards"):
        read_mti(path)


def test_short_row_is_skipped_and_counted(tmp_path):
    rows = [MTI_ROW.format(t=t) for t in (1.0, 2.0, 3.0)]
    rows[1] = rows[1][:20]
    path = write_lines(tmp_path / "a_MTi.log", rows)
    with pytest.warns(
        DataWarning, match=r"a_MTi.log: skipped 1 row\(s\) without 10 columns \(lines 3\)"
    ):
        att = read_mti(path)
    assert np.array_equal(att.t, [1.0, 3.0])


def test_empty_log_is_an_error(tmp_path):
    path = write_lines(tmp_path / "a_DGPS.log", [])
    with pytest.raises(DataError, match=r"a_DGPS.log: no data rows"):
        read_dgps(path)


def test_dvl_status_must_be_a_flag(tmp_path):
    row = DVL_ROW.split()
    row[14] = "7"
    path = write_lines(
        tmp_path / "a_DVL.log", [DVL_ROW, " ".join(row).replace("1093455407.147", "1093455408")]
    )
    with pytest.raises(DataError, match=r"a_DVL.log:3: bottomVelStatus not 0 or 1"):
        read_dvl(path)


def test_dvl_units_and_flags(tmp_path):
    dvl = read_dvl(write_lines(tmp_path / "a_DVL.log", [DVL_ROW]))
    assert np.allclose(dvl.v_mps[0], [0.061, -0.049]) and bool(dvl.valid[0])
    assert abs(dvl.heading_rad[0] - np.deg2rad(90 - 207.7)) < 1e-9


def test_pcd_errors(tmp_path):
    good = "VERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\nWIDTH 2\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS 2\nDATA ascii\n1.0 2.0 0.0\n3.0 4.0 0.0\n"
    (tmp_path / "a.pcd").write_text(good)
    assert np.allclose(read_pcd_xy(tmp_path / "a.pcd"), [[1, 2], [3, 4]])
    (tmp_path / "b.pcd").write_text(good.replace("3.0 4.0 0.0", "3.0 4.0"))
    with pytest.raises(DataError, match=r"b.pcd:12: expected 3 fields"):
        read_pcd_xy(tmp_path / "b.pcd")
    (tmp_path / "c.pcd").write_text(good.replace("POINTS 2", "POINTS 3"))
    with pytest.raises(DataError, match=r"c.pcd: POINTS says 3 but the file has 2"):
        read_pcd_xy(tmp_path / "c.pcd")
    (tmp_path / "d.pcd").write_text(good.replace("3.0 4.0", "3.0 four"))
    with pytest.raises(DataError, match=r"d.pcd:12: non-numeric"):
        read_pcd_xy(tmp_path / "d.pcd")


def test_config_errors_name_file_and_key(tmp_path):
    path = tmp_path / "sonarslam.toml"
    path.write_text("[sonar]\nn_bins = 500\nstep_deg = 'x'\n")
    with pytest.raises(
        DataError,
        match=r"sonarslam.toml:3: \[sonar\] step_deg: must be a number, got the string 'x'",
    ):
        load_dataset_config(path)
    for text in ("[sonar]\nn_bins = '500'\n", '[sonar]\nstep_deg = "1"\n'):  # TOML is typed
        path.write_text(text)
        with pytest.raises(DataError, match=r"sonarslam.toml:2: .* got the string"):
            load_dataset_config(path)
    path.write_text("[mounting.sonar]\nyaw = 3\n")
    with pytest.raises(DataError, match=r"unknown key\(s\) \['yaw'\] in \[mounting.sonar\]"):
        load_dataset_config(path)
    path.write_text("[sonar\n")
    with pytest.raises(DataError, match=r"sonarslam.toml:1: TOML syntax error"):
        load_dataset_config(path)
    path.write_text("[sonar]\nangle_sense = 2\n")
    with pytest.raises(DataError, match=r"angle_sense: must be one of -1, 1"):
        load_dataset_config(path)
    path.write_text("[mounting.dvl]\nyaw_deg = -90.0\n[noise]\ndvl_sigma_mps = 0.02\n")
    cfg = load_dataset_config(path)
    assert abs(cfg.dvl_mounting.yaw_rad + np.pi / 2) < 1e-12 and cfg.noise.dvl_sigma_mps == 0.02
    assert cfg.yaw_rate_source == "gyro"  # neutral default
    for text, message in (
        ("[noise]\ndvl_sigma_mps = -1\n", r"\[noise\] dvl_sigma_mps: must be in \(0, 10\], got -1"),
        ("[mounting.ahrs]\nyaw_deg = nan\n", r"yaw_deg: must be a finite number, got nan"),
        ("[sonar]\nn_bins = 500.5\n", r"n_bins: must be a whole number, got 500.5"),
        ("[sonar]\nbin_size_m = 0\n", r"bin_size_m: must be in \(0, inf\)"),
        (
            "[noise]\ndvl_scatter_window_s = -60\n",
            r"dvl_scatter_window_s: must be in \[0, 3600\], got -60",
        ),
    ):
        path.write_text(text)
        with pytest.raises(DataError, match=message):
            load_dataset_config(path)
    path.write_text("[noise]\ndvl_scatter_window_s = 0\n")  # 0: off, allowed
    assert load_dataset_config(path).noise.dvl_scatter_window_s == 0.0
    path.write_text("[motion]\nyaw_rate_source = 'compass'\n")
    with pytest.raises(
        DataError, match=r"sonarslam.toml:2: \[motion\] yaw_rate_source: must be one"
    ):
        load_dataset_config(path)
    path.write_text("[motion]\nyaw_rate_source = 'heading'\n")
    assert load_dataset_config(path).yaw_rate_source == "heading"
    # what the dump writes reads back the same
    from sonarslam.datasets.config import MARINA_CONFIG, dump_dataset_config

    path.write_text(dump_dataset_config(MARINA_CONFIG))
    back = load_dataset_config(path)
    assert back.yaw_rate_source == MARINA_CONFIG.yaw_rate_source == "heading"
    assert back.noise == MARINA_CONFIG.noise
    for name in ("sonar_mounting", "dvl_mounting", "ahrs_mounting"):  # through degrees
        assert getattr(back, name).yaw_rad == pytest.approx(getattr(MARINA_CONFIG, name).yaw_rad)


@needs_marina
def test_dataset_directory_missing_required_log(tmp_path):
    src = marina_root()
    dst = tmp_path / "m"
    shutil.copytree(src, dst)
    next((dst / "logs").glob("*_DVL.log")).unlink()
    with pytest.raises(DataError, match=re.escape(str(dst)) + r": missing \*_DVL.log"):
        open_dataset(dst)


@needs_marina
def test_keyframe_start_must_be_a_timestamp_row(tmp_path):
    src = marina_root()
    dst = tmp_path / "m"
    shutil.copytree(src, dst)
    csv = dst / "keyframes" / "keyFrameTimeStamps.csv"
    lines = csv.read_text().splitlines()
    k, b, e = lines[5].split(",")
    lines[5] = f"{k},{float(b) + 0.03:.5f},{e}"
    csv.write_text("\n".join(lines) + "\n")
    with pytest.raises(
        DataError, match=r"keyFrameTimeStamps.csv:6: keyframe 5 start .* is no IS_timestamps row"
    ):
        open_dataset(dst)


def test_named_source_needs_the_environment(monkeypatch):
    monkeypatch.delenv("SONARSLAM_DATA", raising=False)
    with pytest.raises(DataError, match=r"needs \$SONARSLAM_DATA"):
        open_dataset("marina")


def test_partial_toml_does_not_inherit_the_marina_calibration(tmp_path):
    from sonarslam.datasets.simulator import simulate

    src = simulate("harbour", seed=2, out_dir=tmp_path / "h", duration_s=30.0)
    toml = src / "sonarslam.toml"
    toml.write_text("[mounting.dvl]\nyaw_deg = -90.0\n")  # everything else left out
    ds = open_dataset(src)
    assert ds.config.sonar_time_offset_s == 0.0
    assert ds.config.sonar_mounting.yaw_rad == 0.0 and ds.config.ahrs_mounting.yaw_rad == 0.0


# --- the whole-file fast path of read_table against the line-by-line reader ----------------------


def _line_reader(path: Path, trust_last_line: bool = False, **kw: object) -> Table:
    """read_table as it was before the whole-file fast path: the line-by-line reader (with the
    fast block of parse_table) on the numbered data lines."""
    numbered, open_end = data_lines(path)
    return parse_table(path, numbered, None if trust_last_line else open_end, **kw)  # type: ignore[arg-type]


def _python_rows(path: Path) -> tuple[np.ndarray, np.ndarray]:
    """The data rows of a clean log by Python's own float() of each field, and their lines: the
    reference neither reader shares a conversion with."""
    rows, numbers = [], []
    for number, raw in enumerate(re.split(rb"\r\n|\r|\n", path.read_bytes()), start=1):
        line = raw.strip(b" \t")
        if line and not line.startswith(b"%"):
            rows.append([float(f) for f in line.split()])
            numbers.append(number)
    return np.array(rows, dtype=np.float64), np.array(numbers)


def _same_table(a: Table, b: Table) -> None:
    assert a.data.dtype == b.data.dtype == np.float64
    assert a.data.shape == b.data.shape
    assert a.data.tobytes() == b.data.tobytes()  # bit for bit (also the sign of a zero)
    assert a.line_numbers.dtype == b.line_numbers.dtype
    assert np.array_equal(a.line_numbers, b.line_numbers)
    assert (a.skipped, a.skipped_lines, a.cut_line) == (b.skipped, b.skipped_lines, b.cut_line)


@needs_marina
def test_fast_path_reads_the_marina_logs_as_the_line_reader():
    logs = marina_root() / "logs"  # type: ignore[operator]
    taken = []
    for path in sorted(logs.glob("*.log")):
        fast = _fast_table(path, path.read_bytes(), None, 1)
        if fast is None:  # the DGPS and SETUP logs end without a line end: read line by line
            assert not path.read_bytes().endswith(b"\n"), path.name
            continue
        taken.append(path.name.rsplit("_", 1)[-1])
        _same_table(fast, _line_reader(path))
        _same_table(read_table(path), _line_reader(path))
        rows, numbers = _python_rows(path)
        assert fast.data.tobytes() == rows.tobytes()
        assert np.array_equal(fast.line_numbers, numbers)
    assert set(taken) == {"DVL.log", "MTi.log", "PID.log", "timestamps.log"}


FAST_CASES = {
    # name: (bytes, whether the fast path takes them)
    "crlf with a head": (b"% a\r\n%\xe9\xff latin-1 head\r\n\r\n1 2.5\r\n3 -4e-3\r\n", True),
    "lf, tabs and runs": (b"  %x\n\t1\t\t2  \n 3 4\t\n", True),
    "blank lines between": (b"1 2\n\n  \t\n3 4\n\n", True),
    "numbers of every shape": (
        b"1. .5 -0 +1e3 1E-3 0.1000000000000000055511151231257827 123456789012345678901 "
        b"2.2250738585072014e-308 4.9e-324 1e-400 -.0e+0\n"
        b"9 9 9 9 9 9 9 9 9 9 9\n",
        True,
    ),
    "no head": (b"1093455224.578 63224578\n1093455224.646 63224646\n", True),
    "a comment below the head": (b"1 2\n% note\n3 4\n", False),
    "a bare cr": (b"1 2\r3 4\n", False),
    "a cut last line": (b"1 2\n3 4", False),
    "a short row": (b"1 2\n3\n5 6\n", False),
    "a field of other bytes": (b"1 2\n3 x\n", False),
    "a vertical tab": (b"1 2\n3\x0b4\n", False),
    "a dangling point": (b"1 2\n. 4\n", False),
    "a dangling exponent": (b"1 2\n1e 4\n", False),
    "two signs": (b"1 2\n+-1 4\n", False),
    "an overflow": (b"1 2\n1e999 4\n", False),
    "only a head": (b"% a\n\n", False),
    "empty": (b"", False),
}


@pytest.mark.parametrize("name", sorted(FAST_CASES))
def test_fast_path_is_the_line_reader_on_crafted_logs(tmp_path, name):
    """Where the whole-file path takes a file, its table is the line reader's bit for bit; where
    it does not, read_table is the line reader (the same table, or the same error and warning)."""
    data, taken = FAST_CASES[name]
    path = tmp_path / "x.log"
    path.write_bytes(data)
    fast = _fast_table(path, data, None, 1)
    assert (fast is not None) == taken
    with warnings.catch_warnings(record=True) as seen_line:
        warnings.simplefilter("always")
        try:
            want: Table | str = _line_reader(path, time_column=None)
        except DataError as exc:
            want = str(exc)
    with warnings.catch_warnings(record=True) as seen_read:
        warnings.simplefilter("always")
        try:
            got: Table | str = read_table(path, time_column=None)
        except DataError as exc:
            got = str(exc)
    assert [str(w.message) for w in seen_read] == [str(w.message) for w in seen_line]
    if isinstance(want, str):
        assert got == want
    else:
        assert isinstance(got, Table)
        _same_table(got, want)
        if fast is not None:
            _same_table(fast, want)
            rows, numbers = _python_rows(path)
            assert fast.data.tobytes() == rows.tobytes()
            assert np.array_equal(fast.line_numbers, numbers)


def test_fast_path_keeps_the_column_count_and_time_errors(tmp_path):
    path = tmp_path / "t.log"
    path.write_bytes(b"% t v\r\n10 1\r\n12 2\r\n11 3\r\n")
    with pytest.raises(DataError, match=r"t\.log:4: time goes backwards"):
        read_table(path)
    path.write_bytes(b"10 1\n-1 2\n")
    with pytest.raises(DataError, match=r"t\.log:2: time -1 s is not a Unix time"):
        read_table(path)
    path.write_bytes(b"10 1 7\n12 2 8\n")
    with pytest.raises(DataError, match="no data rows"):  # both rows have 3 fields
        read_table(path, n_columns=2)
    assert _fast_table(path, path.read_bytes(), 2, 1) is None
    assert _fast_table(path, path.read_bytes(), None, 4) is None
    assert read_table(path, min_columns=3).data.shape == (2, 3)


def _gps_outliers_one_by_one(t_s: np.ndarray, en_m: np.ndarray, gates: GateConfig) -> np.ndarray:
    """The GPS gate's outliers as first written, one fix at a time."""
    out = np.zeros(t_s.size, dtype=bool)
    lo = np.searchsorted(t_s, t_s - GPS_NEIGHBOUR_WINDOW_S, side="left")
    hi = np.searchsorted(t_s, t_s + GPS_NEIGHBOUR_WINDOW_S, side="right")
    for k in range(t_s.size):
        idx = np.concatenate([np.arange(lo[k], k), np.arange(k + 1, hi[k])])
        if idx.size < 2:
            continue
        centre = np.median(en_m[idx], axis=0)
        allowance = gates.gps_max_jump_m + gates.dvl_max_speed_mps * float(
            np.median(np.abs(t_s[idx] - t_s[k]))
        )
        out[k] = float(np.hypot(*(en_m[k] - centre))) > allowance
    return out


def test_gps_outliers_are_those_of_the_fix_by_fix_gate():
    gates = GateConfig()
    rng = np.random.default_rng(28)
    found = 0
    for _ in range(80):
        n = int(rng.integers(0, 80))
        t = np.sort(rng.uniform(0.0, rng.uniform(1.0, 200.0), n))
        en = rng.normal(0.0, rng.uniform(0.1, 30.0), (n, 2))
        if n:
            en[rng.integers(0, n, 3)] += rng.uniform(-200.0, 200.0, (3, 2))
        want = _gps_outliers_one_by_one(t, en, gates)
        assert np.array_equal(_gps_outliers(t, en, gates), want)
        found += int(want.sum())
    assert found > 40  # the cases hold outliers, not only clean tracks


def test_numbers_are_pythons_floats_bit_for_bit():
    """The fields converted arithmetically (up to 15 digits, no exponent) and those left to the
    string conversion are all Python's float() of the field, to the bit (and the sign of a
    zero); a field that is no number is a ValueError."""
    rng = np.random.default_rng(7)
    edge = ["-0", "-0.0", "+0", ".5", "-.25", "1.", "007", "+.0", "-000000000000000.1"]
    edge += ["999999999999999", "0.000000000000001", "123456789012345", "1234567890123456"]
    edge += ["9007199254740993", "0.1000000000000000055511151231257827", "1e5", "-2.5E-3"]
    edge += ["4.9e-324", "1e-400", "255", "0"]
    for _ in range(300):
        fields = []
        for _ in range(int(rng.integers(1, 80))):
            kind = rng.integers(4)
            if kind == 0:
                fields.append(str(rng.integers(0, 256)))
            elif kind == 1:
                fields.append(f"{rng.uniform(-1e6, 1e6):.{rng.integers(0, 16)}f}")
            elif kind == 2:
                digits = "".join(rng.choice(list("0123456789"), int(rng.integers(1, 18))))
                cut = int(rng.integers(0, len(digits) + 1))
                sign = str(rng.choice(["", "-", "+"]))
                fields.append(f"{sign}{digits[:cut]}.{digits[cut:]}")
            else:
                fields.append(str(rng.choice(edge)))
        seps = rng.choice([" ", "\t", "\n", " \t", "\t\t"], len(fields))
        text = "".join(f + str(sep) for f, sep in zip(fields, seps, strict=True)).encode()
        want = np.array([float(f) for f in fields])
        assert _numbers(text).tobytes() == want.tobytes(), fields
    for bad in [b"1 2 .", b"1 +-2", b"1e", b"1 2.3.4", b"- 1", b"1-2", b"+", b"1 -"]:
        with pytest.raises(ValueError):
            _numbers(bad)


def test_numbers_accept_the_grammar_and_give_pythons_floats_on_every_short_field():
    """Every field of ``0 1 9 . + - e`` to 5 characters: one of the grammar NUMBER is converted
    to Python's float() of it, to the bit; one that is not is a ValueError (to 4 characters)."""
    grammar = re.compile(NUMBER)
    good, bad = [], []
    for n in range(1, 6):
        for chars in itertools.product("019.+-e", repeat=n):
            field = "".join(chars)
            (good if grammar.fullmatch(field) else bad).append(field)
    values = _numbers(" ".join(good).encode())
    assert values.tobytes() == np.array([float(f) for f in good]).tobytes()
    for field in (f for f in bad if len(f) <= 4):
        with pytest.raises(ValueError):
            _numbers(f"1 {field} 2".encode())
