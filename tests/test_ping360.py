"""Ping Viewer ``.bin`` logs of a Ping360 with their navigation (issue 30, items 1, 5 and 6): the
simulator's Ping360-shaped run written as a ``.bin`` and a navigation bag (or CSV) reads back
as the directory layout reads, and a bad log is one line or a counted warning."""

from __future__ import annotations

import csv
import json
import math
import shutil
import struct
import tomllib
import warnings
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from sonarslam.datasets.dataset import Dataset
from sonarslam.datasets.errors import DataError, DataWarning
from sonarslam.datasets.geodesy import local_en_to_geodetic
from sonarslam.datasets.ping360 import (
    LOG_HEADER,
    NAV_CSV_COLUMNS,
    Ping360Settings,
    is_ping360_log,
    log_file_name,
    log_start_from_name,
    ping360_table,
    read_nav_csv,
    read_ping360_log,
    sample_spacing_m,
    write_ping360_log,
)
from sonarslam.datasets.simulator.ping360 import ping360_head, write_ping360_run
from sonarslam.datasets.simulator.scenario import make_scenario, simulate_records
from sonarslam.datasets.simulator.writer import write_dataset
from sonarslam.datasets.source import open_dataset
from sonarslam.slam.cli.main import main
from sonarslam.slam.run.sources import dead_reckoning_trajectory

#: The .bin holds whole gradians; the simulator's angles are rounded to 1e-6 rad (its IS log):
#: they agree to half of that (rad).
ANGLE_TOL_RAD = 5e-7


@pytest.fixture(scope="module")
def layout(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A 150 s harbour with a Ping360-shaped head, in the marina layout."""
    scenario = make_scenario("harbour", 3, 150.0)
    scenario = replace(scenario, head=ping360_head(scenario.head))
    return write_dataset(simulate_records(scenario), tmp_path_factory.mktemp("p360") / "layout")


@pytest.fixture(scope="module")
def direct(layout: Path) -> Dataset:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DataWarning)
        return open_dataset(layout)


@pytest.fixture(scope="module")
def binlog(direct: Dataset, layout: Path) -> Path:
    return write_ping360_run(direct, layout.parent / "bin", layout)


def _open(path: Path, **kw: object) -> Dataset:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DataWarning)
        return open_dataset(path, **kw)  # type: ignore[arg-type]


def _same_beams(d: Dataset, ref: Dataset) -> None:
    np.testing.assert_array_equal(d.beams.intensities, ref.beams.intensities)  # u8: exact
    np.testing.assert_array_equal(d.beams.t_s, ref.beams.t_s)  # whole ms both ways: exact
    miss = np.angle(np.exp(1j * (d.beams.transducer_angle_rad - ref.beams.transducer_angle_rad)))
    assert np.max(np.abs(miss)) < ANGLE_TOL_RAD


def test_the_head_is_a_ping360s() -> None:
    head = ping360_head(make_scenario("harbour", 0, 10.0).head)
    # 500 samples every 5333 ticks of 25 ns at 1500 m/s (the marina head's 0.1 m, quantised)
    assert head.n_bins == 500 and head.bin_size_m == sample_spacing_m(5333, 1500.0) == 0.09999375
    assert head.step_rad == pytest.approx(2 * math.pi / 200) and head.angle_sense == -1
    pool = ping360_head(make_scenario("pool", 0, 10.0).head)
    assert pool.bin_size_m == pytest.approx(0.012) and pool.step_rad == pytest.approx(math.pi / 200)


def test_a_bin_with_its_nav_bag_reads_as_the_directory(binlog: Path, direct: Dataset) -> None:
    assert is_ping360_log(binlog) and binlog.name == log_file_name(
        int(round(direct.beams.t_s[0] * 1000)) - 500
    )
    d = _open(binlog)
    assert d.config == direct.config and d.calibration == str(binlog.parent / "sonarslam.toml")
    _same_beams(d, direct)
    np.testing.assert_array_equal(d.dvl.v_mps, direct.dvl.v_mps)
    np.testing.assert_array_equal(d.attitude.t, direct.attitude.t)
    assert d.truth is not None and d.gps is not None and direct.gps is not None
    np.testing.assert_allclose(d.gps.en_m, direct.gps.en_m, rtol=0, atol=1e-6)
    faults = {k: v for k, v in d.report.counts.items() if k.startswith("ping360_")}
    assert set(faults.values()) == {0}
    a, b = dead_reckoning_trajectory(d), dead_reckoning_trajectory(direct)
    np.testing.assert_array_equal(a.t_s, b.t_s)
    np.testing.assert_allclose(a.poses_wTb, b.poses_wTb, rtol=0, atol=1e-9)


def _nav_csv(d: Dataset, path: Path) -> Path:
    """``d``'s DVL, AHRS and GPS as a navigation CSV, one sensor a row."""
    assert d.gps is not None
    lat, lon = local_en_to_geodetic(d.gps.en_m[:, 0], d.gps.en_m[:, 1], *d.gps.origin_lat_lon_deg)
    rows: list[tuple[float, int, dict[str, str]]] = []
    for i, t in enumerate(d.dvl.t):
        v = d.dvl.v_mps[i]
        cells = {"dvl_vx_mps": repr(float(v[0])), "dvl_vy_mps": repr(float(v[1]))}
        rows.append((t, 1, {**cells, "dvl_valid": str(int(d.dvl.valid[i]))}))
    for i, t in enumerate(d.attitude.t):
        rows.append(
            (
                t,
                0,
                {
                    "ahrs_yaw_enu_rad": repr(float(d.attitude.yaw_rad[i])),
                    "ahrs_yaw_rate_rad_per_s": repr(float(d.attitude.yaw_rate_rad_per_s[i])),
                },
            )
        )
    for i, t in enumerate(d.gps.t):
        rows.append(
            (t, 2, {"gps_lat_deg": repr(float(lat[i])), "gps_lon_deg": repr(float(lon[i]))})
        )
    rows.sort(key=lambda r: (r[0], r[1]))
    with path.open("w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=list(NAV_CSV_COLUMNS))
        w.writeheader()
        for t, _, cells in rows:
            w.writerow({"t_s": repr(float(t)), **cells})
    return path


def test_a_nav_csv_gives_the_bags_navigation_and_run_takes_it(
    binlog: Path, direct: Dataset, tmp_path: Path
) -> None:
    nav = _nav_csv(direct, tmp_path / "nav.csv")
    d = _open(binlog, nav=nav)
    _same_beams(d, direct)
    np.testing.assert_array_equal(d.dvl.v_mps, direct.dvl.v_mps)
    np.testing.assert_array_equal(d.dvl.valid, direct.dvl.valid)
    np.testing.assert_array_equal(d.attitude.yaw_rad, direct.attitude.yaw_rad)
    assert d.gps is not None and direct.gps is not None
    np.testing.assert_allclose(d.gps.en_m, direct.gps.en_m, rtol=0, atol=1e-6)
    a, b = dead_reckoning_trajectory(d), dead_reckoning_trajectory(direct)
    np.testing.assert_allclose(a.poses_wTb, b.poses_wTb, rtol=0, atol=1e-9)
    out = tmp_path / "run"
    assert main(["run", str(binlog), "--nav", str(nav), "--out", str(out), "--quiet"]) == 0
    m = json.loads((out / "metrics.json").read_text())
    assert m["evaluation"] == "gps and truth" and m["ate_truth_mean_m"] < 3.0
    # calibrate --write keeps the .bin's [ping360] table, its nav relative to the new file
    kept = ping360_table(binlog, binlog.parent / "new.toml", nav)
    assert tomllib.loads(kept) == {"ping360": {"nav": str(nav), "speed_of_sound_mps": 1500.0}}
    assert tomllib.loads(ping360_table(binlog, binlog.parent / "new.toml"))["ping360"]["nav"] == (
        "nav.bag"
    )
    # a bad cell is named by its line
    lines = nav.read_text().splitlines()
    lines[5] = lines[5].replace(lines[5].split(",")[0], "soon", 1)
    (tmp_path / "bad.csv").write_text("\n".join(lines) + "\n")
    with pytest.raises(DataError, match=r"bad.csv:6: t_s = 'soon' is not a finite number"):
        read_nav_csv(tmp_path / "bad.csv")


def test_utf8_strings_and_time_of_day_stamps_crossing_midnight(tmp_path: Path) -> None:
    """Older logs stamp the time of day (Ping Viewer before July 2019): a stamp more than 12 h
    earlier has crossed midnight; UTF-8 strings read as UTF-16 ones."""
    start_ms = 1_700_006_390_000  # 23:59:50 UTC
    name = tmp_path / log_file_name(start_ms)
    assert name.name == "20231114-235950000.bin"
    tod = start_ms % 86_400_000
    stamps = np.array([tod + 1000, tod + 5000, tod + 9900, 100, 4000])  # across midnight
    bins = np.arange(5 * 300, dtype=np.int64).reshape(5, 300).astype(np.uint8)
    for enc in ("utf-8", "utf-16-be"):
        write_ping360_log(name, stamps, np.array([0, 1, 2, 3, 399]), bins, 80, encoding=enc)
        with warnings.catch_warnings():
            warnings.simplefilter("error")  # midnight is no fault: counted, not warned
            log = read_ping360_log(name)
        assert log.stamps == "time_of_day" and log.encoding == enc
        assert log.counts["ping360_midnight_wraps"] == 1
        t_ms = np.rint(log.beams.t_s * 1000).astype(np.int64)
        np.testing.assert_array_equal(t_ms - start_ms, [1000, 5000, 9900, 10100, 14000])
        np.testing.assert_allclose(log.beams.transducer_angle_rad[-1], 399 * math.pi / 200)
        np.testing.assert_array_equal(log.beams.intensities, bins)
        assert log.bin_size_m == pytest.approx(1500 * 80 * 25e-9 / 2)  # 1.5 mm
    elapsed = read_ping360_log(name, Ping360Settings(stamps="elapsed"))
    assert elapsed.stamps == "elapsed"
    # read as elapsed time, the first stamp is nearly a day after the file name's time
    assert elapsed.beams.t_s[0] == (start_ms + tod + 1000) / 1000.0


def _message(msg_id: int, payload: bytes) -> bytes:
    frame = struct.pack("<2sHHBB", b"BR", len(payload), msg_id, 1, 0) + payload
    return frame + struct.pack("<H", sum(frame) & 0xFFFF)


def _records(path: Path) -> list[tuple[int, bytes]]:
    """(byte offset, bytes) of each record of a UTF-16 log written by write_ping360_log."""
    data = path.read_bytes()
    pos = 4 + 2 * len(LOG_HEADER) + 4 + 5 * 4 + 2 * len("sonarslam") + 8
    out = []
    while pos < len(data):
        start = pos
        pos += 4 + 24
        (n,) = struct.unpack(">I", data[pos : pos + 4])
        pos += 4 + n
        out.append((start, data[start:pos]))
    return out


@pytest.fixture
def small(tmp_path: Path) -> Path:
    """Six beams of 200 samples, elapsed stamps 0.1 s apart."""
    p = tmp_path / "20240502-103107250.bin"
    bins = (np.arange(6 * 200).reshape(6, 200) % 251).astype(np.uint8)
    write_ping360_log(p, np.arange(6) * 100 + 50, np.arange(6) * 2, bins, 1000)
    return p


def test_bad_messages_are_counted_and_dropped(small: Path) -> None:
    recs = _records(small)
    data = bytearray(small.read_bytes())
    # record 1: a sample changed, the checksum not (a serial glitch)
    data[recs[1][0] + 4 + 24 + 4 + 8 + 14 + 7] ^= 0xFF
    # record 3: a message id the protocol does not define, well framed
    unknown = _message(9999, b"\x00\x01")
    stamp = recs[3][1][: 4 + 24]
    bad = stamp + struct.pack(">I", len(unknown)) + unknown
    out = bytes(data[: recs[3][0]]) + bad + bytes(data[recs[3][0] + len(recs[3][1]) :])
    # a common message (1: ack) is another record, not a fault
    ack = stamp + struct.pack(">I", 12) + _message(1, b"\x05\x00")
    small.write_bytes(out + ack)
    with pytest.warns(DataWarning) as caught:
        log = read_ping360_log(small)
    text = " ".join(str(w.message) for w in caught)
    assert (
        f"1 message(s) with a wrong checksum, dropped (their bytes changed on the link) ({len(recs[1][1]) - 32} bytes); the first in record 1 (byte offset {recs[1][0]})"
        in text
    )
    assert f"the first in record 3 (byte offset {recs[3][0]})" in text
    assert log.counts["ping360_checksum_errors"] == 1
    assert log.counts["ping360_unknown_messages"] == 1
    assert log.counts["ping360_other_messages"] == 1
    # the beams left are at 0, 4, 8, 10 gradians: the median step is 4
    assert len(log.beams) == 4 and log.step_grad == 4


def test_a_log_cut_short_keeps_its_whole_records(small: Path) -> None:
    recs = _records(small)
    whole = read_ping360_log(small)
    small.write_bytes(small.read_bytes()[: recs[4][0] + 100])
    with pytest.warns(DataWarning, match=rf"ends inside record 4 \(byte offset {recs[4][0]}\)"):
        cut = read_ping360_log(small)
    assert cut.counts["ping360_truncated_records"] == 1
    np.testing.assert_array_equal(cut.beams.intensities, whole.beams.intensities[:4])
    np.testing.assert_array_equal(cut.beams.t_s, whole.beams.t_s[:4])


@pytest.mark.parametrize(
    ("damage", "message"),
    [
        ("empty", r"an empty file, not a Ping Viewer log"),
        ("header", r"not a Ping Viewer log: it does not start with the string"),
        ("stamp", r"record 2 \(byte offset \d+\): time stamp '00x00:00.250' is not hh:mm:ss.zzz"),
        ("back", r"record 3 \(byte offset \d+\): its stamp is 2.000 s earlier .* clock jump"),
        ("length", r"record 1 \(byte offset \d+\): a record of 4294967040 bytes"),
    ],
)
def test_a_bad_log_is_one_error_naming_the_record(small: Path, damage: str, message: str) -> None:
    recs = _records(small)
    data = bytearray(small.read_bytes())
    if damage == "empty":
        data = bytearray()
    elif damage == "header":
        data[10] ^= 0x20
    elif damage == "stamp":
        data[recs[2][0] + 4 + 5] = ord("x")
    elif damage == "length":
        data[recs[1][0] + 28 : recs[1][0] + 32] = struct.pack(">I", 0xFFFFFF00)
    else:
        bins = np.zeros((4, 200), np.uint8)
        stamps = [50, 2150, 2300, 300]
        periods = [1000, 1000, 1000, 1000]
        parts = []
        for k in range(4):
            tmp = small.parent / f"part{k}.bin"
            write_ping360_log(tmp, np.array([stamps[k]]), np.array([k]), bins[:1], periods[k])
            parts.append(_records(tmp)[0][1])
        data = bytearray(small.read_bytes()[: recs[0][0]] + b"".join(parts))
    small.write_bytes(bytes(data))
    with pytest.raises(DataError, match=message) as err:
        read_ping360_log(small)
    assert str(small) in str(err.value)


def test_the_date_comes_from_the_file_name_or_the_settings(small: Path, tmp_path: Path) -> None:
    assert log_start_from_name(small) == 1_714_645_867_250  # 2024-05-02 10:31:07.250 UTC
    assert log_start_from_name(small, utc_offset_h=2.0) == 1_714_645_867_250 - 7_200_000
    renamed = tmp_path / "sonar.bin"
    shutil.copy(small, renamed)
    with pytest.raises(DataError, match=r"sonar.bin: the file name holds no Ping Viewer date"):
        read_ping360_log(renamed)
    log = read_ping360_log(renamed, Ping360Settings(start="2024-05-02T12:31:07.250+02:00"))
    assert log.start_ms == 1_714_645_867_250 and log.beams.t_s[0] == 1_714_645_867.3


def test_a_bin_alone_is_a_still_head_and_clocks_must_meet(
    binlog: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Without navigation a .bin is read as a still head at --start (said plainly): info,
    plot-scans, extract and run --backend dr work on it, the closed loops are refused."""
    alone = tmp_path / binlog.name
    shutil.copy(binlog, alone)
    with pytest.warns(DataWarning, match=r"no navigation .* read as a still head at --start"):
        still = open_dataset(alone)
    assert still.still and still.gps is None and len(still.beams) > 1000
    start = replace(still, start_enu=(3.0, -2.0, math.radians(30.0)))
    track = dead_reckoning_trajectory(start)
    assert track.covs is None and track.span_s == pytest.approx(still.nav_span_s, abs=1e-9)
    poses = track.poses(still.beams.t_s)
    np.testing.assert_allclose(poses - poses[:1], 0.0, atol=1e-12)
    np.testing.assert_allclose(poses[0], [3.0, -2.0, math.radians(30.0)], atol=1e-12)
    out = tmp_path / "out"
    assert main(["info", str(alone)]) == 0
    said = capsys.readouterr().out
    assert "start pose: no navigation: a still head at (0, 0) m heading 0 deg" in said
    assert main(["run", str(alone), "--backend", "ekf", "--out", str(out), "--quiet"]) == 2
    err = capsys.readouterr().err  # every kind of navigation --nav takes (a review: BAG_OR_CSV)
    assert "ekf needs a DVL and an AHRS: --nav FILE" in err
    assert all(
        k in err for k in ("ROS bag", "CSV", ".tlog", "dataflash", "A50 JSON", "QGroundControl CSV")
    )
    args = ["--start", "3,-2,30", "--out"]
    assert main(["run", str(alone), *args, str(out / "dr"), "--quiet"]) == 0
    said = capsys.readouterr().out
    assert "start pose: no navigation: a still head at (3, -2) m heading 30 deg" in said
    dr = np.loadtxt(out / "dr" / "dr.tum")
    np.testing.assert_allclose(dr[:, 1:3], [[3.0, -2.0]] * len(dr), atol=1e-9)
    assert main(["plot-scans", str(alone), *args, str(out / "scans.png")]) == 0
    assert "with dr poses" in capsys.readouterr().out
    assert main(["extract", str(alone), *args, str(out / "lines"), "--quiet"]) == 0
    assert json.loads((out / "lines" / "extract.json").read_text())["poses"] == "dr"
    nav = binlog.parent / "nav.bag"
    assert _open(alone, nav=nav).calibration.startswith("neutral")  # never the marina's
    # the file name read in the wrong zone: the beams miss the navigation, said in one line
    (tmp_path / "sonarslam.toml").write_text('[ping360]\nnav = "x.bag"\nutc_offset_h = 5\n')
    shutil.copy(nav, tmp_path / "x.bag")
    with pytest.raises(DataError, match=r"miss the navigation .* by \+5.00 h"):
        _open(alone)


def test_auto_device_data_beams_and_bad_settings(small: Path) -> None:
    """auto_device_data (2301, the head scanning on its own) is a beam as device_data is;
    a [ping360] key that is not one is named."""
    from brping import PingMessage, definitions

    recs = _records(small)
    msg = PingMessage(definitions.PING360_AUTO_DEVICE_DATA)
    for name, value in dict(
        mode=1, gain_setting=0, angle=398, transmit_duration=10, sample_period=1000,
        transmit_frequency=750, start_angle=0, stop_angle=399, num_steps=2, delay=0,
        number_of_samples=200, data_length=200,
    ).items():  # fmt: skip
        setattr(msg, name, value)
    msg.data = bytearray(range(200))
    raw = bytes(msg.pack_msg_data())
    record = recs[0][1][: 4 + 24] + struct.pack(">I", len(raw)) + raw
    data = small.read_bytes()
    small.write_bytes(data[: recs[0][0]] + record + data[recs[0][0] + len(recs[0][1]) :])
    log = read_ping360_log(small)
    assert len(log.beams) == 6
    assert log.beams.transducer_angle_rad[0] == pytest.approx(398 * math.pi / 200)
    np.testing.assert_array_equal(log.beams.intensities[0], np.arange(200))
    (small.parent / "sonarslam.toml").write_text("[ping360]\nsound_speed = 1480\n")
    with pytest.raises(DataError, match=r"sonarslam.toml: unknown key\(s\) \['sound_speed'\]"):
        _open(small, nav=small.parent / "nav.csv")
    (small.parent / "sonarslam.toml").write_text("[ping360]\nspeed_of_sound_mps = 900\n")
    with pytest.raises(DataError, match=r"\[ping360\]: .*speed_of_sound_mps"):
        _open(small, nav=small.parent / "nav.csv")


def test_the_navigation_bag_is_read_through_rosbags_public_role_reader() -> None:
    """ping360.py reads its navigation bag with ``read_roles`` (rosbag.py's public, documented
    role reader) and reaches into none of rosbag.py's private names."""
    import ast

    import sonarslam.datasets.ping360 as ping360
    import sonarslam.datasets.rosbag as rosbag

    tree = ast.parse(Path(ping360.__file__).read_text(encoding="utf-8"))
    private = sorted(
        {
            alias.name
            for node in ast.walk(tree)
            if isinstance(node, ast.ImportFrom) and (node.module or "").endswith("rosbag")
            for alias in node.names
            if alias.name.startswith("_")
        }
        | {
            node.attr
            for node in ast.walk(tree)
            if isinstance(node, ast.Attribute)
            and isinstance(node.value, ast.Name)
            and node.value.id in ("rb", "rosbag")
            and node.attr.startswith("_")
        }
    )
    assert private == []
    assert "read_roles" in rosbag.__all__ and rosbag.read_roles.__doc__
    assert ping360.read_roles is rosbag.read_roles


def test_a_wrong_speed_of_sound_is_named_with_its_line_and_in_the_length_warning(
    binlog: Path, direct: Dataset, tmp_path: Path
) -> None:
    """A new user's review: the simulator's sonarslam.toml pins [sonar] bin_size_m, so
    another [ping360] speed_of_sound_mps was an error naming the file but not its line; and
    the odometry check's length ratio pointed at [sonar] bin_size_m, which a Ping Viewer log
    does not read (its bin size is the speed of sound times the sample period)."""
    from sonarslam.slam.eval.loops import OdometryCheck
    from sonarslam.slam.run.run import _warn_odometry

    folder = tmp_path / "sos"
    shutil.copytree(binlog.parent, folder)
    toml = folder / "sonarslam.toml"
    text = toml.read_text().replace("speed_of_sound_mps = 1500.0", "speed_of_sound_mps = 1400.0")
    toml.write_text(text)
    line = 1 + text.splitlines().index(next(s for s in text.splitlines() if "bin_size_m" in s))
    with pytest.raises(DataError) as err:
        _open(folder / binlog.name)
    assert str(err.value).startswith(f"{toml}:{line}: [sonar] n_bins 500, bin_size_m")
    # left out, the log's bin size at 1400 m/s is taken: 1400/1500 of the layout's
    toml.write_text("\n".join(s for s in text.splitlines() if "bin_size_m" not in s) + "\n")
    d = _open(folder / binlog.name)
    assert d.config.sonar.bin_size_m == pytest.approx(direct.config.sonar.bin_size_m * 1400 / 1500)
    short = OdometryCheck(12, 7, 0.0, 0.933, 0.2, 0.005)  # what a run of it measures
    with pytest.warns(UserWarning, match=r"x0\.933 .*\[ping360\] speed_of_sound_mps") as record:
        _warn_odometry(d, short)
    assert "bin_size_m" not in str(record[0].message)
    with pytest.warns(UserWarning, match=r"x0\.933 .*\[sonar\] bin_size_m"):
        _warn_odometry(direct, short)


def test_a_step_that_is_not_the_logs_is_refused_with_its_line(binlog: Path, tmp_path: Path) -> None:
    """A sonarslam.toml's [sonar] step_deg twice the log's own step (its step_grad): the sector
    store, the Hough resolution and the scans count beams by it, and it was taken over the
    log's in silence; now refused naming its line, and left out the log's is taken."""
    folder = tmp_path / "step"
    shutil.copytree(binlog.parent, folder)
    toml = folder / "sonarslam.toml"
    text = toml.read_text()
    own = _open(binlog).config.sonar.step_rad
    lines = [s for s in text.splitlines() if not s.startswith("step_deg")]
    at = lines.index("[sonar]") + 1
    lines.insert(at, f"step_deg = {2 * math.degrees(own)!r}")
    toml.write_text("\n".join(lines) + "\n")
    with pytest.raises(DataError) as err:
        _open(folder / binlog.name)
    assert str(err.value).startswith(f"{toml}:{at + 1}: [sonar] step_deg"), str(err.value)
    assert "the log's head steps by" in str(err.value)


# -- Ping Viewer's logs as written (issue 41, item 1) ------------------------------------------

PERSIAN_ZERO = "\u06f0"


def _record(stamp: str, data: bytes) -> bytes:
    """One UTF-16 record: a stamp and the bytes the link read."""
    text = stamp.encode("utf-16-be")
    return struct.pack(">I", len(text)) + text + struct.pack(">I", len(data)) + data


def test_digits_of_any_script_are_read_as_their_ascii_digit() -> None:
    from sonarslam.datasets.ping360 import ascii_digits

    # Extended Arabic-Indic (Persian), Arabic-Indic, Devanagari, full-width: str.isdecimal
    for zero in ("\u06f0", "\u0660", "\u0966", "\uff10"):
        text = "".join(chr(ord(zero) + d) for d in (2, 0, 2, 4)) + "-x:."
        assert ascii_digits(text) == "2024-x:."
    assert ascii_digits("²") == "²"  # a superscript is a digit, not a decimal one: kept


@pytest.mark.parametrize("encoding", ["utf-16-be", "utf-8"])
def test_split_records_persian_digits_and_range_changes_read_whole(
    tmp_path: Path, encoding: str
) -> None:
    """What Ping Viewer writes (FileLink::writeData logs each serial read, not each message;
    Qt 5 stamps in the system locale's digits): beams whose bytes straddle records are joined,
    the stamps and the file name in Persian digits read, the ranges 2 -> 15 -> 60 m read as
    three segments of their own bin size; only two messages whose middles the link lost are
    dropped, counted as cut short."""
    rng = np.random.default_rng(41)
    n = 120
    bins = rng.integers(0, 256, (n, 1200)).astype(np.uint8)
    periods = np.repeat([88, 666, 2666], 40)  # Ping Viewer's sample periods for 2, 15, 60 m
    counts = np.repeat([1200, 1000, 1200], 40)
    stamps = 500 + 37 * np.arange(n)
    start_ms = 1_700_000_000_123
    name = tmp_path / log_file_name(start_ms, zero=PERSIAN_ZERO)
    assert name.name == "۲۰۲۳۱۱۱۴-۲۲۱۳۲۰۱۲۳.bin"
    write_ping360_log(
        name, stamps, np.arange(n) * 2 % 400, bins, periods, encoding,
        n_samples=counts, split_rng=np.random.default_rng(7), zero=PERSIAN_ZERO, lose=(10, 70),
    )  # fmt: skip
    with pytest.warns(DataWarning) as caught:
        log = read_ping360_log(name)
    said = [str(w.message) for w in caught]
    assert len(said) == 1 and "2 message(s) cut short, dropped: their bytes end before" in said[0]
    assert log.counts["ping360_cut_messages"] == 2
    sent = [8 + 14 + int(counts[k]) + 2 for k in (10, 70)]  # header, fields, data, checksum
    # what arrived of each: its first and last thirds
    assert log.counts["ping360_dropped_bytes"] == sum(m - (2 * m // 3 - m // 3) for m in sent)
    faults = [k for k, v in log.counts.items() if v and "cut" not in k and "dropped" not in k]
    assert faults == []
    keep = np.setdiff1d(np.arange(n), [10, 70])
    assert len(log.beams) == keep.size and log.records > 3 * n  # a beam over several records
    np.testing.assert_array_equal(np.rint(log.beams.t_s * 1000) - start_ms, stamps[keep])
    for i, k in enumerate(keep):
        np.testing.assert_array_equal(log.beams.intensities[i, : counts[k]], bins[k, : counts[k]])
    assert not log.beams.intensities[40:78, 1000:].any()  # the 15 m beams' padding
    sizes = [sample_spacing_m(t, 1500.0) for t in (88, 666, 2666)]
    assert [(g.beams, g.n_bins, g.bin_size_m) for g in log.segments] == [
        (39, 1200, sizes[0]), (39, 1000, sizes[1]), (40, 1200, sizes[2])
    ]  # fmt: skip
    assert log.segments[1].t0_s == (start_ms + stamps[40]) / 1000.0
    assert log.segments[2].range_m == pytest.approx(60.0, abs=0.02)  # whole ticks: 59.985 m
    assert log.beams.bin_size_m is not None
    np.testing.assert_array_equal(log.beams.bin_size_m, np.repeat(sizes, [39, 39, 40]))
    # the head is the farthest-reaching segment's; rows as wide as the most samples
    assert log.bin_size_m == sizes[2] and log.n_bins == 1200 and log.sample_period_ticks == 2666


def test_bytes_in_no_message_are_counted_by_their_cause(small: Path) -> None:
    """A log opened mid-message begins with the end of one (stray bytes); a flipped byte
    breaks one message's checksum; the log cut inside its last message: each dropped, counted
    under its own cause and named so, and nothing else is lost."""
    recs = _records(small)
    whole = read_ping360_log(small)
    body = bytearray(b"".join(r[1] for r in recs))
    tail = recs[0][1][32 + 150 :]  # the end of a message: no "BR" in it
    assert b"BR" not in tail
    # record 2's message: a sample flipped (its checksum no longer holds)
    body[recs[2][0] - recs[0][0] + 32 + 10 + 14 + 50] ^= 0x01
    data = small.read_bytes()[: recs[0][0]] + _record("00:00:00.010", tail) + bytes(body)
    small.write_bytes(data[: len(data) - 40])  # inside the last message
    with pytest.warns(DataWarning) as caught:
        log = read_ping360_log(small)
    said = " | ".join(str(w.message) for w in caught)
    assert f"{len(tail)} byte(s) outside any message, dropped" in said
    assert "1 message(s) with a wrong checksum, dropped" in said
    assert "the log ends inside record 6" in said  # its record, cut: dropped with it
    c = log.counts
    assert (c["ping360_stray_bytes"], c["ping360_checksum_errors"]) == (len(tail), 1)
    assert c["ping360_truncated_records"] == 1 and c["ping360_cut_messages"] == 0
    np.testing.assert_array_equal(log.beams.intensities, whole.beams.intensities[[0, 1, 3, 4]])


def test_span_takes_part_of_any_source(
    binlog: Path, layout: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """--span T0,T1 (s from the start of the navigation) takes that part of a .bin or of a
    directory: its beams, navigation and GPS; a span with nothing in it is one line."""
    whole = _open(binlog)
    t0 = whole.nav_span_s[0]
    for source in (binlog, layout):
        part = _open(source, span_s=(20.0, 60.0))
        assert part.nav_span_s[0] >= t0 + 20.0 - 0.2 and part.nav_span_s[1] <= t0 + 60.0
        assert part.beams.t_s[0] >= t0 + 20.0 and part.beams.t_s[-1] <= t0 + 60.0
        inside = (whole.beams.t_s >= t0 + 20.0) & (whole.beams.t_s <= t0 + 60.0)
        assert len(part.beams) == np.count_nonzero(inside) > 500
        assert part.gps is not None and part.gps.t[0] >= t0 + 20.0
    out = tmp_path / "run"
    args = ["run", str(binlog), "--span", "20,60", "--out", str(out), "--quiet"]
    assert main(args) == 0
    m = json.loads((out / "metrics.json").read_text())
    assert m["provenance"]["span_s"] == [20.0, 60.0] and m["data_s"] < 40.0 + 1e-6
    assert main(["info", str(binlog), "--span", "400,500"]) == 1
    assert "--span 400,500 (s from the start of the navigation, whose span is 0-1" in (
        capsys.readouterr().err
    )


def test_a_log_that_ends_inside_a_message_keeps_the_whole_ones(tmp_path: Path) -> None:
    """Records split as the link reads: the log closed between two records of one message
    drops that message, counted as unfinished and named so; the beams before it are whole."""
    p = tmp_path / "20240502-103107250.bin"
    bins = (np.arange(6 * 200).reshape(6, 200) % 251).astype(np.uint8)
    write_ping360_log(
        p, np.arange(6) * 100, np.arange(6) * 2, bins, 1000, split_rng=np.random.default_rng(5)
    )
    recs = _records(p)
    p.write_bytes(p.read_bytes()[: recs[-1][0]])  # without its last record
    with pytest.warns(DataWarning, match=r"1 message the log ends inside, dropped \(\d+ bytes\)"):
        log = read_ping360_log(p)
    assert log.counts["ping360_unfinished_messages"] == 1
    np.testing.assert_array_equal(log.beams.intensities, bins[:5])
