"""ROS bags in and out (issue 30, items 1, 5 and 6): the simulator's run written as a ROS 1 bag
and ROS 2 MCAP and sqlite3 bags reads back as the directory reads, and a bad bag is one line."""

from __future__ import annotations

import hashlib
import json
import math
import re
import shutil
import warnings
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from sonarslam.datasets.config import dump_dataset_config
from sonarslam.datasets.errors import DataError, DataWarning
from sonarslam.datasets.rosbag import (
    CLOCK_JUMP_S,
    CUSTOM_MSG_DEFINITIONS,
    OLDER_DEFINITIONS,
    _decode,
    _messages,
    _stamp_of,
    _typestore,
    bag_config,
    bag_topics,
    is_bag,
    open_bag,
    transform_msg,
    write_bag,
)
from sonarslam.datasets.source import Dataset, open_dataset
from sonarslam.slam.cli.main import main
from sonarslam.slam.run.sources import dead_reckoning_trajectory

#: float32 transducer angles in LaserScan (angle_min): the one rounding of the round trip (rad)
ANGLE_TOL_RAD = 4e-7
#: GPS through latitude/longitude and back (m)
GPS_TOL_M = 1e-6


@pytest.fixture(scope="module")
def harbour(simulated: Callable[..., Path]) -> Path:
    return simulated("harbour", 2, 300.0)


@pytest.fixture(scope="module")
def layout(harbour: Path) -> Dataset:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DataWarning)
        return open_dataset(harbour)


def _bag(layout: Dataset, harbour: Path, folder: Path, kind: str) -> Path:
    """The harbour written as a ``kind`` bag, with its sonarslam.toml and truth.json."""
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / "run.bag" if kind == "ros1" else folder / "bag"
    write_bag(layout, path, kind)
    beside = folder if kind == "ros1" else path
    shutil.copy(harbour / "truth.json", beside / "truth.json")
    (beside / "sonarslam.toml").write_text(dump_dataset_config(bag_config(layout.config)))
    return path


@pytest.fixture(scope="module")
def bags(
    layout: Dataset, harbour: Path, tmp_path_factory: pytest.TempPathFactory
) -> dict[str, Path]:
    root = tmp_path_factory.mktemp("bags")
    return {k: _bag(layout, harbour, root / k, k) for k in ("ros1", "mcap", "sqlite3")}


@pytest.mark.parametrize("kind", ["ros1", "mcap", "sqlite3"])
def test_a_bag_reads_as_the_directory(kind: str, bags: dict[str, Path], layout: Dataset) -> None:
    bag = bags[kind]
    assert is_bag(bag)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DataWarning)
        d = open_dataset(bag)
    # REP-103 angles: the head turns the other way round, each beam's bearing is the same
    assert d.config == bag_config(layout.config) and d.config.sonar.angle_sense == 1
    np.testing.assert_array_equal(d.beams.intensities, layout.beams.intensities)
    np.testing.assert_array_equal(d.beams.t_s, layout.beams.t_s)  # ns stamps of these times
    bearing_miss = np.angle(
        np.exp(
            1j
            * (
                d.config.sonar.bearing_rad(d.beams.transducer_angle_rad)
                - layout.config.sonar.bearing_rad(layout.beams.transducer_angle_rad)
            )
        )
    )
    assert np.max(np.abs(bearing_miss)) < ANGLE_TOL_RAD
    np.testing.assert_array_equal(d.dvl.v_mps, layout.dvl.v_mps)
    np.testing.assert_array_equal(d.dvl.valid, layout.dvl.valid)
    np.testing.assert_array_equal(d.attitude.t, layout.attitude.t)
    yaw_miss = np.angle(np.exp(1j * (d.attitude.yaw_rad - layout.attitude.yaw_rad)))
    assert np.max(np.abs(yaw_miss)) < 1e-12
    assert d.gps is not None and layout.gps is not None
    np.testing.assert_allclose(d.gps.en_m, layout.gps.en_m, rtol=0, atol=GPS_TOL_M)
    assert d.report.counts == {
        **layout.report.counts,
        **{
            f"{r}_{c}": 0
            for r in ("sonar", "dvl", "imu", "gps")
            for c in ("out_of_order", "repeated")
        },
    }
    # the same trajectory: dead reckoning reads no beams, so to the last bit
    a, b = dead_reckoning_trajectory(d), dead_reckoning_trajectory(layout)
    np.testing.assert_array_equal(a.t_s, b.t_s)
    np.testing.assert_allclose(a.poses_wTb, b.poses_wTb, rtol=0, atol=1e-9)


def test_a_ros1_bag_carries_ros1_message_definitions(bags: dict[str, Path]) -> None:
    """A ROS 1 bag's connections hold ROS 1's definitions (a ``Header`` with ``seq``) and their
    MD5 sums, as ``rosbag`` and ``rostopic`` check them (issue 32's review: the ROS 2 ones were
    written, ``LaserScan`` 27099baa... instead of ROS 1's 90c7ef2d...)."""
    from rosbags.rosbag1 import Reader

    with Reader(bags["ros1"]) as reader:
        conns = {c.msgtype: c for c in reader.connections}
    scan = conns["sensor_msgs/msg/LaserScan"]
    assert scan.digest == "90c7ef2dc6895d81024acba2ac42f369"
    assert "uint32 seq" in scan.msgdef.data
    # the rest of the ROS 1 standard (Noetic's MD5 sums)
    assert conns["sensor_msgs/msg/Imu"].digest == "6a62c6daae103f4ff57a132d6f95cec2"
    assert conns["sensor_msgs/msg/NavSatFix"].digest == "2d3a8cd499b9b4a0249fb98fd05cfa48"


def test_info_lists_the_roles_and_run_takes_a_bag(
    bags: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    roles = {t.topic: (t.msgtype, t.role, t.count) for t in bag_topics(bags["ros1"])}
    assert roles["/sonar/scan"][:2] == ("sensor_msgs/msg/LaserScan", "sonar")
    assert roles["/gps/fix"][1] == "gps" and roles["/imu/data"][2] == 3000
    assert main(["info", str(bags["mcap"])]) == 0
    out = capsys.readouterr().out
    assert "/dvl/twist" in out and "geometry_msgs/msg/TwistWithCovarianceStamped" in out
    # the settings' source is the sonarslam.toml beside the bag, for a bag file and a directory
    assert main(["info", str(bags["ros1"])]) == 0
    out = capsys.readouterr().out
    assert re.search(r"\[mounting\.sonar\] x_m .*sonarslam\.toml", out), out
    assert "neutral default" not in out
    assert main(["run", str(bags["sqlite3"]), "--out", str(tmp_path / "r"), "--quiet"]) == 0
    m = json.loads((tmp_path / "r" / "metrics.json").read_text())
    assert m["calibration"].endswith("sonarslam.toml") and m["evaluation"] == "gps and truth"
    # a bag file's provenance: its bytes and the two files beside it that the run reads
    assert (
        main(["run", str(bags["ros1"]), "--backend", "dr", "--out", str(tmp_path / "f"), "--quiet"])
        == 0
    )
    p = json.loads((tmp_path / "f" / "metrics.json").read_text())["provenance"]
    folder = bags["ros1"].parent
    read = ("run.bag", "sonarslam.toml", "truth.json")
    assert p["dataset_files"] == {
        n: hashlib.sha256((folder / n).read_bytes()).hexdigest() for n in read
    }
    assert p["dataset_file_count"] == 3 and p["dataset_sha256"] != hashlib.sha256().hexdigest()


def test_calibrate_ahrs_on_a_bag_without_a_dvl_compass_is_one_line_naming_the_bag(
    bags: dict[str, Path], harbour: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A bag's DVL message has no compass heading: ``calibrate --ahrs`` printed a NaN
    mounting and then "yaw_rad must be in [-6.28319, 6.28319], got nan" without a file (a
    new user's review). Now one line names the bag and the setting to give instead; the layout,
    whose DVL log has the compass, still calibrates."""
    assert main(["calibrate", str(bags["ros1"]), "--ahrs", "--quiet"]) == 1
    out, err = capsys.readouterr()
    assert "nan" not in out
    (line,) = [ln for ln in err.splitlines() if not ln.startswith("warning:")]
    assert str(bags["ros1"]) in line and "compass heading" in line
    assert "[mounting.ahrs] yaw_deg" in line
    assert main(["calibrate", str(harbour), "--ahrs", "--quiet"]) == 0
    assert "nan deg (configured" not in capsys.readouterr().out


def test_the_length_ratio_on_a_bag_names_its_messages_range(
    bags: dict[str, Path], layout: Dataset
) -> None:
    """A bag's bin size is its sonar messages' range over their bins, which ``[sonar]
    bin_size_m`` cannot override (a DataError): the odometry check's length-ratio warning
    named that setting on a bag too."""
    from sonarslam.slam.eval.loops import OdometryCheck
    from sonarslam.slam.run.run import _warn_odometry

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DataWarning)
        d = open_dataset(bags["ros1"])
    short = OdometryCheck(12, 7, 0.0, 0.933, 0.2, 0.005)
    with pytest.warns(UserWarning, match=r"x0\.933 .*sonar messages give it") as record:
        _warn_odometry(d, short)
    assert "[sonar] bin_size_m" not in str(record[0].message)
    with pytest.warns(UserWarning, match=r"x0\.933 .*\[sonar\] bin_size_m"):
        _warn_odometry(layout, short)


def test_a_head_that_disagrees_with_the_bag_names_the_file_that_set_it(
    bags: dict[str, Path], tmp_path: Path
) -> None:
    """``[sonar] bin_size_m`` in a --config over a bag whose own sonarslam.toml leaves it to the
    bag: the error names the --config file, not the bag's."""
    over = tmp_path / "m_bin.toml"
    over.write_text("[sonar]\nbin_size_m = 10.0\n")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DataWarning)
        with pytest.raises(DataError, match=r"bin_size_m 10: the bag's beams have") as e:
            open_bag(bags["ros1"], config_override=over)
    assert str(e.value).startswith(f"{over}:")


def test_simulate_writes_a_bag(tmp_path: Path) -> None:
    out = tmp_path / "sim"
    assert main(["simulate", "pool", "--duration", "30", "--out", str(out), "--bag", "mcap"]) == 0
    assert (out / "metadata.yaml").is_file() and (out / "sonarslam.toml").is_file()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DataWarning)
        d = open_dataset(out)
    assert len(d.beams) > 100 and d.truth is not None


def test_simulate_leaves_the_gps_out_of_any_bag_when_asked(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Only --preset caves wrote a bag without GPS: the default shape always had a NavSatFix
    topic, so a run on it was never one without GPS. --no-gps leaves it out of every output
    (the layout's DGPS log, any bag), the truth kept; its help says so."""
    args = ["simulate", "pool", "--duration", "20", "--out"]
    assert main([*args, str(tmp_path / "gps"), "--bag", "ros1"]) == 0
    assert main([*args, str(tmp_path / "bag"), "--bag", "ros1", "--no-gps"]) == 0
    assert main([*args, str(tmp_path / "layout"), "--no-gps"]) == 0
    assert not list((tmp_path / "layout").glob("*_DGPS.log"))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DataWarning)
        with_gps = open_dataset(next((tmp_path / "gps").glob("*.bag")))
        without = open_dataset(next((tmp_path / "bag").glob("*.bag")))
        layout = open_dataset(tmp_path / "layout")
    assert with_gps.gps is not None and with_gps.gps.t.size > 10
    assert without.gps is None and layout.gps is None
    assert without.truth is not None and layout.truth is not None
    assert len(without.beams) == len(with_gps.beams) > 100
    capsys.readouterr()
    with pytest.raises(SystemExit):
        main(["simulate", "--help"])
    sim_help = " ".join(capsys.readouterr().out.split())
    assert "--no-gps leave the GPS out" in sim_help and "(--bag, any --preset)" in sim_help


def _write_ros1(
    d: Dataset,
    path: Path,
    change: Callable[[str, int, float], float],
    edit: Callable[[str, int, Any], None] | None = None,
) -> Path:
    """``d`` as a ROS 1 bag whose header stamps are ``change(role, index, t)`` (the receive
    times stay ``t``): out-of-order stamps and clock jumps; ``edit(role, index, msg)`` changes a
    message in place before it is written."""
    from rosbags.rosbag1 import Writer

    store = _typestore()
    types = {
        "sonar": "sensor_msgs/msg/LaserScan",
        "dvl": "geometry_msgs/msg/TwistWithCovarianceStamped",
        "imu": "sensor_msgs/msg/Imu",
        "gps": "sensor_msgs/msg/NavSatFix",
    }
    counts = dict.fromkeys(types, 0)
    with Writer(path) as w:
        conns = {r: w.add_connection(f"/{r}", ty, typestore=store) for r, ty in types.items()}
        for t, role, msg in _messages(store, d):
            msg.header.stamp = _stamp_of(store, change(role, counts[role], t))
            if edit is not None:
                edit(role, counts[role], msg)
            counts[role] += 1
            w.write(conns[role], int(round(t * 1e9)), store.serialize_ros1(msg, types[role]))
    return path


@pytest.fixture(scope="module")
def short(layout: Dataset) -> Dataset:
    """The harbour's first 60 s (bad bags are made of it)."""
    t0 = layout.nav_span_s[0]
    keep_a, keep_d = layout.attitude.t < t0 + 60, layout.dvl.t < t0 + 60
    from dataclasses import replace

    from sonarslam.datasets.records import AttitudeSeries, DvlSeries

    a, v = layout.attitude, layout.dvl
    return replace(
        layout,
        beams=layout.beams.between(0.0, t0 + 60),
        attitude=AttitudeSeries(a.t[keep_a], a.yaw_rad[keep_a], a.yaw_rate_rad_per_s[keep_a]),
        dvl=DvlSeries(v.t[keep_d], v.v_mps[keep_d], v.valid[keep_d], v.heading_rad[keep_d]),
        gps=None,
    )


def test_out_of_order_stamps_are_counted_and_sorted(short: Dataset, tmp_path: Path) -> None:
    def swap(role: str, i: int, t: float) -> float:
        return t + 0.15 if role == "imu" and i == 20 else t  # later than the next (10 Hz)

    bag = _write_ros1(short, tmp_path / "ooo.bag", swap)
    with pytest.warns(DataWarning, match=r"topic /imu \(imu\): 1 message\(s\) stamped earlier"):
        d = open_bag(bag)
    assert d.report.counts["imu_out_of_order"] == 1
    assert np.all(np.diff(d.attitude.t) >= 0)


def test_the_step_between_beams_is_the_beams_own(short: Dataset, tmp_path: Path) -> None:
    """A head stepping 0.9 deg (a Micron's or a Ping360's finer step) in a bag without a
    ``[sonar] step_deg``: the step is the beams' own (it was the default 1.8 deg, and the sector
    store, the Hough resolution and the scans counted beams by it: half the sector, in silence);
    a sonarslam.toml whose step_deg says otherwise is refused naming its line."""
    from dataclasses import replace

    from sonarslam.datasets.records import BeamSeries

    b = short.beams
    fine = BeamSeries(
        b.t_s, np.mod(0.5 * np.unwrap(b.transducer_angle_rad), 2.0 * np.pi), b.intensities
    )
    d = replace(short, beams=fine)
    bag = tmp_path / "fine" / "run.bag"
    bag.parent.mkdir()
    write_bag(d, bag, "ros1")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DataWarning)
        opened = open_bag(bag)
    assert math.degrees(opened.config.sonar.step_rad) == pytest.approx(0.9, abs=1e-9)
    (bag.parent / "sonarslam.toml").write_text(
        "[noise]\ngps_sigma_m = 1.0\n\n[sonar]\nstep_deg = 1.8\n"
    )
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DataWarning)
        with pytest.raises(
            DataError,
            match=r"sonarslam.toml:5: \[sonar\] step_deg 1.8: the bag's beams step by 0.9 deg",
        ):
            open_bag(bag)
    (bag.parent / "sonarslam.toml").write_text("[sonar]\nstep_deg = 0.9\n")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DataWarning)
        assert open_bag(bag).config.sonar.step_rad == pytest.approx(math.radians(0.9))


def test_a_clock_jump_is_an_error_naming_the_topic_and_message(
    short: Dataset, tmp_path: Path
) -> None:
    def jump(role: str, i: int, t: float) -> float:
        return t + 3600.0 if role == "dvl" and i >= 40 else t

    bag = _write_ros1(short, tmp_path / "jump.bag", jump)
    with pytest.raises(
        DataError, match=r"jump.bag: topic /dvl \(dvl\) message 40: its stamp jumps \+3600"
    ):
        open_bag(bag)
    assert CLOCK_JUMP_S == 1.0


def test_laser_scan_angles_in_degrees_are_an_error_naming_the_message(
    short: Dataset, tmp_path: Path
) -> None:
    """A LaserScan whose angle_min is in degrees read as radians gave a run without a line
    that said nothing; refused at its first message beyond 2 pi, naming bag, topic, index."""
    degrees: list[float] = []

    def in_degrees(role: str, i: int, msg: Any) -> None:
        if role == "sonar":
            msg.angle_min = msg.angle_max = math.degrees(msg.angle_min)
            degrees.append(msg.angle_min)

    bag = _write_ros1(short, tmp_path / "deg.bag", _same, in_degrees)
    first = next(i for i, a in enumerate(degrees) if abs(a) > 2.0 * np.pi)
    with pytest.raises(
        DataError,
        match=rf"deg\.bag: topic /sonar \(sensor_msgs/msg/LaserScan\) message {first}:"
        r" angle_min [0-9.]+ is beyond 2 pi rad: degrees",
    ):
        open_bag(bag)


def _same(role: str, i: int, t: float) -> float:
    return t


def test_an_imu_without_orientation_is_an_error_naming_the_message(
    short: Dataset, tmp_path: Path
) -> None:
    """A raw IMU topic (REP-145: orientation_covariance[0] = -1, a zero quaternion) read as a
    heading would be a heading of 0 for the whole run: refused at its first message."""

    def raw(role: str, i: int, msg: Any) -> None:
        if role == "imu":
            msg.orientation_covariance[0] = -1.0
            msg.orientation.x = msg.orientation.y = msg.orientation.z = msg.orientation.w = 0.0

    bag = _write_ros1(short, tmp_path / "raw.bag", _same, raw)
    with pytest.raises(
        DataError, match=r"raw.bag: topic /imu \(sensor_msgs/msg/Imu\) message 0: .*REP-145"
    ):
        open_bag(bag)

    def zero(role: str, i: int, msg: Any) -> None:
        if role == "imu" and i == 7:
            msg.orientation.x = msg.orientation.y = msg.orientation.z = msg.orientation.w = 0.0

    bag = _write_ros1(short, tmp_path / "zero.bag", _same, zero)
    with pytest.raises(DataError, match=r"message 7: orientation \(0, 0, 0, 0\) is not a unit"):
        open_bag(bag)


def test_an_ned_heading_beside_an_enu_gyro_is_an_error(layout: Dataset, tmp_path: Path) -> None:
    """An orientation whose heading is NED's (clockwise from North) beside the ENU gyro turns
    against it: refused, where it would have been a mirrored trajectory without a word. The
    harbour's own bag (both ENU) passes the same check."""
    turned = float(np.sum(np.abs(np.diff(np.unwrap(layout.attitude.yaw_rad)))))
    assert turned > math.radians(180.0)  # the check has turns to judge

    def ned(role: str, i: int, msg: Any) -> None:
        if role == "imu":
            q = msg.orientation
            yaw = math.atan2(2.0 * (q.w * q.z + q.x * q.y), 1.0 - 2.0 * (q.y * q.y + q.z * q.z))
            heading = 0.5 * math.pi - yaw
            q.x, q.y, q.z, q.w = 0.0, 0.0, math.sin(0.5 * heading), math.cos(0.5 * heading)

    bag = _write_ros1(layout, tmp_path / "ned.bag", _same, ned)
    with pytest.raises(
        DataError,
        match=r"ned.bag: topic /imu \(imu\): the orientation's heading"
        r" turns against angular_velocity.z \(correlation -[01]\.",
    ):
        open_bag(bag)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DataWarning)
        open_bag(_write_ros1(layout, tmp_path / "enu.bag", _same))  # no error


def test_a_mounting_left_out_among_given_ones_is_said(
    short: Dataset, harbour: Path, tmp_path: Path
) -> None:
    """A sonarslam.toml that gives the sonar's mounting but not the DVL's nor the AHRS's leaves
    those at the identity: said by name (the harbour's DVL is truly turned), not run silently;
    the full file says nothing of the kind."""
    bag = write_bag(short, tmp_path / "run.bag", "ros1")
    full = (harbour / "sonarslam.toml").read_text(encoding="utf-8")
    (tmp_path / "sonarslam.toml").write_text(_without_mountings(full, keep="sonar"))
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", DataWarning)
        open_bag(bag)
    said = [str(w.message) for w in caught if "are the identity" in str(w.message)]
    assert len(said) == 1 and "the dvl, ahrs mounting(s)" in said[0]
    assert "[mounting.dvl], [mounting.ahrs]" in said[0]
    (tmp_path / "sonarslam.toml").write_text(full)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", DataWarning)
        open_bag(bag)
    assert not [w for w in caught if "are the identity" in str(w.message)]


def test_missing_role_wrong_type_and_truncated_bags_are_one_line(
    short: Dataset, bags: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    from dataclasses import replace

    # no sonar topic: the bag's topics are listed with the types that would do
    no_sonar = replace(short, beams=short.beams[:0])
    bag = tmp_path / "nosonar.bag"
    from rosbags.rosbag1 import Writer

    store = _typestore()
    with Writer(bag) as w:
        c = w.add_connection("/imu", "sensor_msgs/msg/Imu", typestore=store)
        c2 = w.add_connection(
            "/dvl", "geometry_msgs/msg/TwistWithCovarianceStamped", typestore=store
        )
        for t, role, msg in _messages(store, no_sonar):
            if role == "imu":
                w.write(c, int(t * 1e9), store.serialize_ros1(msg, "sensor_msgs/msg/Imu"))
            elif role == "dvl":
                w.write(
                    c2,
                    int(t * 1e9),
                    store.serialize_ros1(msg, "geometry_msgs/msg/TwistWithCovarianceStamped"),
                )
    with pytest.raises(
        DataError,
        match=r"nosonar.bag: no topic for the sonar \(types: sonar: sensor_msgs/msg/LaserScan",
    ):
        open_bag(bag)
    # a topic named for a role it cannot play
    topics = tmp_path / "topics.toml"
    topics.write_text('[topics]\nsonar = "/imu/data"\n')
    with pytest.raises(
        DataError, match=r"topic /imu/data is sensor_msgs/msg/Imu, which cannot be the sonar"
    ):
        open_bag(bags["ros1"], topics_file=topics)
    topics.write_text('[topics]\ndvl = "/nowhere"\n')
    with pytest.raises(DataError, match=r"\[topics\] dvl = '/nowhere': no such topic"):
        open_bag(bags["ros1"], topics_file=topics)
    topics.write_text('[topic]\nsonar = "/sonar"\n')  # a misspelt table is not ignored
    with pytest.raises(
        DataError, match=r"topics.toml: no \[topics\] table \(its tables: \['topic'\]\)"
    ):
        open_bag(bags["ros1"], topics_file=topics)
    # a bag cut short: one line on the command line, no traceback
    cut = tmp_path / "cut"
    cut.mkdir()
    data = bags["ros1"].read_bytes()
    (cut / "run.bag").write_bytes(data[: len(data) // 2])
    assert main(["info", str(cut / "run.bag")]) == 1
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "cut/run.bag" in err and "Traceback" not in err
    mcap = next(bags["mcap"].glob("*.mcap"))
    (cut / "half.mcap").write_bytes(mcap.read_bytes()[: mcap.stat().st_size // 2])
    assert main(["run", str(cut / "half.mcap"), "--out", str(tmp_path / "o"), "--quiet"]) == 1
    err = capsys.readouterr().err
    assert "half.mcap" in err and "Traceback" not in err


@pytest.mark.parametrize("kind", ["ros1", "sqlite3", "ros1_gradians"])
def test_ping360_messages_give_beams_in_radians_and_metres(
    kind: str, short: Dataset, tmp_path: Path
) -> None:
    """SonarPing360 (gradians, profile_data, range) in a ROS 2 sqlite3 bag, whose types come
    from CUSTOM_MSG_DEFINITIONS; SonarEcho (radians) in a ROS 1 bag, which carries its own.
    ``ros1_gradians``: SonarEcho.angle in gradians as the ROS 1 ping360_sonar node publishes
    it (read as radians it was a run of dead reckoning that said nothing): refused at the first
    message beyond 2 pi, naming the bag, topic, message and the unit."""
    from rosbags.rosbag1 import Writer as Writer1
    from rosbags.rosbag2 import StoragePlugin
    from rosbags.rosbag2 import Writer as Writer2

    store = _typestore()
    T = store.types
    ping = (
        "bluerobotics_sonar_msgs/msg/SonarPing360"
        if kind == "sqlite3"
        else "ping360_sonar/msg/SonarEcho"
    )
    ros1 = kind.startswith("ros1")
    types = {
        "sonar": ping,
        "dvl": "geometry_msgs/msg/TwistWithCovarianceStamped",
        "imu": "sensor_msgs/msg/Imu",
    }
    n, range_m = short.config.sonar.n_bins, 50
    grads: list[int] = []

    def sonar(msg: object) -> object:
        grad = int(round(float(msg.angle_min) / (np.pi / 200.0))) % 400  # type: ignore[attr-defined]
        grads.append(grad)
        bins = np.asarray(msg.intensities, dtype=np.uint8)  # type: ignore[attr-defined]
        h = msg.header  # type: ignore[attr-defined]
        if kind == "sqlite3":
            return T[ping](
                header=h,
                distance=0.0,
                mode=1,
                gain_setting=1,
                angle=grad,
                transmit_duration=10,
                sample_period=80,
                transmit_frequency=750,
                range=float(range_m),
                profile_data=bins,
            )
        return T[ping](
            header=h,
            angle=float(grad) if kind == "ros1_gradians" else grad * np.pi / 200.0,
            gain=1,
            number_of_samples=n,
            transmit_frequency=750,
            speed_of_sound=1500,
            range=range_m,
            intensities=bins,
        )

    def serialize(msg: object, ty: str) -> bytes:
        return store.serialize_ros1(msg, ty) if ros1 else store.serialize_cdr(msg, ty)

    path = tmp_path / ("p.bag" if ros1 else "p")
    w = Writer1(path) if ros1 else Writer2(path, version=9, storage_plugin=StoragePlugin.SQLITE3)
    with w:
        conns = {r: w.add_connection(f"/{r}", ty, typestore=store) for r, ty in types.items()}
        for t, role, msg in _messages(store, short):
            if role in conns:
                out = sonar(msg) if role == "sonar" else msg
                w.write(conns[role], int(round(t * 1e9)), serialize(out, types[role]))
    if kind == "ros1_gradians":
        first = next(i for i, g in enumerate(grads) if g > 2.0 * np.pi)
        with pytest.raises(
            DataError,
            match=rf"p\.bag: topic /sonar \(ping360_sonar/msg/SonarEcho\) message {first}:"
            rf" angle {grads[first]} is beyond 2 pi rad: gradians \(0-399",
        ):
            open_bag(path)
        return
    with pytest.warns(DataWarning, match="neutral") as said:
        d = open_bag(path)
    # the sonarslam.toml to write: inside a bag directory, beside a bag file
    toml = (path if path.is_dir() else tmp_path) / "sonarslam.toml"
    assert any(f"--write {toml}, docs/data.md" in str(w.message) for w in said)
    np.testing.assert_allclose(
        d.beams.transducer_angle_rad, np.array(grads) * np.pi / 200.0, atol=1e-6
    )
    np.testing.assert_array_equal(d.beams.intensities, short.beams.intensities)
    assert d.config.sonar.n_bins == n and d.config.sonar.bin_size_m == pytest.approx(range_m / n)


# -- other DVL and sonar types, mountings from the transforms, the caves preset ---------------

#: The caves data set's DVL as its ROS 1 bag defines it (the ROS 2 port lowers the names)
LINKQUEST_ROS1 = (
    "std_msgs/Header header\nstring errCode\nint32[4] dataGood\nfloat64[4] altitudeBeam\n"
    "float64[4] bottomVelocityBeam\nfloat64[4] waterVelocityBeam\nfloat64[4] waterVelocityCredit\n"
    "float64[3] velocityInst\nint32 velocityInstFlag\nfloat64[3] velocityEarth\n"
    "int32 velocityEarthFlag\nfloat64[3] waterVelocityInst\nint32 waterVelocityInstFlag\n"
    "float64[3] waterVelocityEarth\nint32 waterVelocityEarthFlag\nfloat64 roll\nfloat64 pitch\n"
    "float64 heading\nfloat64 altitude\nfloat64 temperature\nfloat64 pressure\n"
    "float64 salinity\nfloat64 soundSpeed\nstring rawData\n"
)


def _write(
    path: Path,
    kind: str,
    store: object,
    topics: dict[str, tuple[str, str]],
    messages: list[tuple[float, str, object]],
) -> Path:
    """``messages`` (time, role, message) on ``topics`` (role -> (topic, type)) as a bag."""
    from rosbags.rosbag1 import Writer as Writer1
    from rosbags.rosbag2 import StoragePlugin
    from rosbags.rosbag2 import Writer as Writer2

    w = (
        Writer1(path)
        if kind == "ros1"
        else Writer2(path, version=9, storage_plugin=StoragePlugin.SQLITE3)
    )
    ser = store.serialize_ros1 if kind == "ros1" else store.serialize_cdr  # type: ignore[attr-defined]
    with w:
        conns = {
            r: w.add_connection(topic, ty, typestore=store) for r, (topic, ty) in topics.items()
        }
        for t, role, msg in messages:
            w.write(conns[role], int(round(t * 1e9)), ser(msg, topics[role][1]))
    return path


def _tf(store: object, t: float, parent: str, child: str, x: float, y: float, yaw: float) -> object:
    """A transform 0.1 m above its parent (a tilt-free offset the reader must ignore)."""
    return transform_msg(store, t, parent, child, x, y, yaw, z_m=0.1)


def test_water_linked_and_marine_acoustic_dvls_and_a_projected_sonar_image(
    short: Dataset, tmp_path: Path
) -> None:
    """Water Linked's DVL (velocity_valid, fom) in a ROS 2 sqlite3 bag read with the driver's
    definition; marine_acoustic_msgs Dvl (bottom mode, >= 3 good beams) with one-beam
    ProjectedSonarImage sonar in a ROS 1 bag."""
    store = _typestore()
    T = store.types
    vec = T["geometry_msgs/msg/Vector3"]
    lost = set(range(5, 9))  # DVL messages without bottom lock
    n = short.config.sonar.n_bins
    ranges = (np.arange(1, n + 1) * short.config.sonar.bin_size_m).astype(np.float32)
    for kind, dvl_type in (
        ("sqlite3", "dvl_msgs/msg/DVL"),
        ("ros1", "marine_acoustic_msgs/msg/Dvl"),
    ):
        msgs: list[tuple[float, str, object]] = []
        k = 0
        for t, role, msg in _messages(store, short):
            h = msg.header  # type: ignore[attr-defined]
            if role == "dvl":
                v = msg.twist.twist.linear  # type: ignore[attr-defined]
                ok = k not in lost and bool(short.dvl.valid[k])
                if dvl_type == "dvl_msgs/msg/DVL":  # the A50's frame: y to the right
                    msg = T[dvl_type](
                        header=h,
                        time=0.0,
                        velocity=vec(x=v.x, y=-v.y, z=0.0),
                        fom=0.1,
                        covariance=np.zeros(9),
                        altitude=3.0,
                        beams=[],
                        velocity_valid=ok,
                        status=0,
                        time_of_validity=0,
                        time_of_transmission=0,
                        form="json_v3",
                    )
                else:
                    msg = T[dvl_type](
                        header=h,
                        velocity_mode=1,
                        dvl_type=0,
                        velocity=v,
                        velocity_covar=np.full(9, -1.0),
                        altitude=3.0,
                        course_gnd=0.0,
                        speed_gnd=0.0,
                        num_good_beams=4 if ok else 2,
                        sound_speed=1500.0,
                        beam_ranges_valid=False,
                        beam_velocities_valid=False,
                        beam_unit_vec=[vec(x=0.0, y=0.0, z=1.0)] * 4,
                        range=np.zeros(4),
                        range_covar=np.zeros(4, np.float32),
                        beam_quality=np.zeros(4, np.float32),
                        beam_velocity=np.zeros(4, np.float32),
                        beam_velocity_covar=np.zeros(4, np.float32),
                    )
                k += 1
            elif role == "sonar" and kind == "ros1":
                a = float(msg.angle_min)  # type: ignore[attr-defined]
                msg = T["marine_acoustic_msgs/msg/ProjectedSonarImage"](
                    header=h,
                    ping_info=T["marine_acoustic_msgs/msg/PingInfo"](
                        frequency=7e5,
                        sound_speed=1500.0,
                        tx_beamwidths=np.zeros(0, np.float32),
                        rx_beamwidths=np.zeros(0, np.float32),
                    ),
                    beam_directions=[vec(x=0.0, y=-math.sin(a), z=math.cos(a))],
                    ranges=ranges,
                    image=T["marine_acoustic_msgs/msg/SonarImageData"](
                        is_bigendian=False,
                        dtype=0,
                        beam_count=1,
                        data=np.asarray(msg.intensities, dtype=np.uint8),  # type: ignore[attr-defined]
                    ),
                )
            msgs.append((t, role, msg))
        sonar = (
            "marine_acoustic_msgs/msg/ProjectedSonarImage"
            if kind == "ros1"
            else "sensor_msgs/msg/LaserScan"
        )
        topics = {
            "sonar": ("/s", sonar),
            "dvl": ("/d", dvl_type),
            "imu": ("/i", "sensor_msgs/msg/Imu"),
        }
        bag = _write(tmp_path / ("b.bag" if kind == "ros1" else "b"), kind, store, topics, msgs)
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            d = open_bag(bag)
        said = " ".join(str(w.message) for w in caught)
        valid = short.dvl.valid.copy()
        valid[sorted(lost)] = False
        np.testing.assert_array_equal(d.dvl.valid, valid)
        np.testing.assert_array_equal(d.dvl.v_mps[valid], short.dvl.v_mps[valid])
        np.testing.assert_array_equal(d.beams.intensities, short.beams.intensities)
        # both types give REP-103 angles: the bearings are the directory's
        assert d.config.sonar.angle_sense == 1
        got = d.config.sonar.bearing_rad(d.beams.transducer_angle_rad)
        miss = np.angle(
            np.exp(1j * (got - short.config.sonar.bearing_rad(short.beams.transducer_angle_rad)))
        )
        assert np.max(np.abs(miss)) < 1e-6
        if dvl_type == "dvl_msgs/msg/DVL":  # fom 0.1 m/s above the neutral 0.05: said
            assert "median 0.1 m/s" in said and "dvl_sigma_mps = 0.05" in d.calibration
        else:  # a covariance of -1 is unknown: nothing to say
            assert "dvl_sigma_mps" not in d.calibration


def _without_mountings(toml: str, keep: str = "") -> str:
    """A sonarslam.toml's text without its [mounting.*] tables (but ``[mounting.<keep>]``)."""
    out, skip = [], False
    for line in toml.splitlines():
        if line.startswith("["):
            skip = line.startswith("[mounting.") and line != f"[mounting.{keep}]"
        if not skip:
            out.append(line)
    return "\n".join(out) + "\n"


def _caves_bag(short: Dataset, path: Path, kind: str, tf_topic: str) -> Path:
    """``short`` in the shape of the caves data set: its topics and types (the Micron and the
    SeaKing as LaserScan, two Imu, the LinkQuest DVL, the vehicle's /odometry), its frames
    (``sparus`` -> sensors) on ``tf_topic``, no GPS; the mountings are the simulator's."""
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    store = _typestore()
    if kind == "ros1":  # the original's spelling, carried by the bag
        store = get_typestore(Stores.ROS2_HUMBLE)
        store.register(
            get_types_from_msg(LINKQUEST_ROS1, "cirs_girona_cala_viuda/msg/LinkquestDvl")
        )
    T = store.types
    c = short.config
    mounts = {
        "sonar_micron": c.sonar_mounting,
        "dvl_linkquest": c.dvl_mounting,
        "imu_adis": c.ahrs_mounting,
        "sonar_seaking": c.sonar_mounting,
    }
    topics = {
        "sonar": ("/sonar_micron_ros", "sensor_msgs/msg/LaserScan"),
        "seaking": ("/sonar_seaking_ros", "sensor_msgs/msg/LaserScan"),
        "dvl": ("/dvl_linkquest", "cirs_girona_cala_viuda/msg/LinkquestDvl"),
        "odometry": ("/odometry", "nav_msgs/msg/Odometry"),
        "imu": ("/imu_adis_ros", "sensor_msgs/msg/Imu"),
        "xsens": ("/imu_xsens_mti_ros", "sensor_msgs/msg/Imu"),
        "tf": (tf_topic, "tf2_msgs/msg/TFMessage"),
    }
    frames = {"sonar": "sonar_micron", "dvl": "dvl_linkquest", "imu": "imu_adis"}
    lower = kind != "ros1"
    msgs: list[tuple[float, str, object]] = []
    if tf_topic == "/tf_static":
        t0 = float(short.attitude.t[0]) - 0.01
        tfs = [_tf(store, t0, "sparus", f, m.x_m, m.y_m, m.yaw_rad) for f, m in mounts.items()]
        msgs.append((t0, "tf", T["tf2_msgs/msg/TFMessage"](transforms=tfs)))
    for t, role, msg in _messages(store, short):
        msg.header.frame_id = frames[role]  # type: ignore[attr-defined]
        if role == "dvl":
            v = msg.twist.twist.linear  # type: ignore[attr-defined]
            ok = int(msg.twist.covariance[0] >= 0)  # type: ignore[attr-defined]
            z4, z3 = np.zeros(4), np.zeros(3)
            fields = {
                "errCode": "",
                "dataGood": np.ones(4, np.int32),
                "altitudeBeam": z4,
                "bottomVelocityBeam": z4,
                "waterVelocityBeam": z4,
                "waterVelocityCredit": z4,
                "velocityInst": np.array([v.x, v.y, 0.0]),
                "velocityInstFlag": ok,
                "velocityEarth": z3,
                "velocityEarthFlag": 0,
                "waterVelocityInst": z3,
                "waterVelocityInstFlag": 0,
                "waterVelocityEarth": z3,
                "waterVelocityEarthFlag": 0,
                "roll": 0.0,
                "pitch": 0.0,
                "heading": 0.0,
                "altitude": 3.0,
                "temperature": 14.0,
                "pressure": 0.0,
                "salinity": 0.0,
                "soundSpeed": 1500.0,
                "rawData": "",
            }
            if lower:
                fields = {k.lower(): val for k, val in fields.items()}
            h = msg.header  # type: ignore[attr-defined]
            msgs.append(
                (t, "dvl", T["cirs_girona_cala_viuda/msg/LinkquestDvl"](header=h, **fields))
            )
            odo = T["nav_msgs/msg/Odometry"](
                header=T["std_msgs/msg/Header"](stamp=h.stamp, frame_id="world"),
                child_frame_id="sparus",
                pose=T["geometry_msgs/msg/PoseWithCovariance"](
                    pose=T["geometry_msgs/msg/Pose"](
                        position=T["geometry_msgs/msg/Point"](x=0.0, y=0.0, z=0.0),
                        orientation=T["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.0, w=1.0),
                    ),
                    covariance=np.zeros(36),
                ),
                twist=msg.twist,  # type: ignore[attr-defined]
            )
            msgs.append((t + 1e-4, "odometry", odo))
            continue
        msgs.append((t, role, msg))
        if role == "sonar":
            msgs.append((t, "seaking", msg))
        if role == "imu":
            msgs.append((t, "xsens", msg))
            if tf_topic == "/tf":  # the vehicle's pose and the sensor offsets, at 10 Hz
                tfs = [_tf(store, t, "world", "sparus", 0.0, 0.0, 0.0)]
                tfs += [
                    _tf(store, t, "sparus", f, m.x_m, m.y_m, m.yaw_rad) for f, m in mounts.items()
                ]
                msgs.append((t, "tf", T["tf2_msgs/msg/TFMessage"](transforms=tfs)))
    msgs.sort(key=lambda m: m[0])
    return _write(path, kind, store, topics, msgs)


@pytest.mark.parametrize(("kind", "tf_topic"), [("ros1", "/tf"), ("sqlite3", "/tf_static")])
def test_the_caves_preset_and_mountings_from_the_transforms(
    kind: str,
    tf_topic: str,
    short: Dataset,
    harbour: Path,
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
) -> None:
    """A bag in the caves data set's shape is read by its preset (no [topics]: the Micron, the
    ADIS IMU, the LinkQuest DVL although /odometry and a second sonar and IMU fit too) with the
    mountings from its transforms; a sonarslam.toml's [mounting.X] table wins over them."""
    bag = _caves_bag(short, tmp_path / ("caves.bag" if kind == "ros1" else "caves"), kind, tf_topic)
    beside = tmp_path if kind == "ros1" else bag
    toml = (harbour / "sonarslam.toml").read_text()
    # the ROS 1 case keeps no mounting in its file; the ROS 2 case keeps the sonar's, moved
    keep = "" if kind == "ros1" else "sonar"
    (beside / "sonarslam.toml").write_text(
        _without_mountings(toml, keep).replace("x_m = 0.3", "x_m = 0.5")
    )
    roles = {t.topic: t.role for t in bag_topics(bag)}
    assert roles["/sonar_micron_ros"] == "sonar" and roles["/sonar_seaking_ros"] == ""
    assert roles["/dvl_linkquest"] == "dvl" and roles["/odometry"] == ""
    assert roles["/imu_adis_ros"] == "imu" and roles["/imu_xsens_mti_ros"] == ""
    d = open_bag(bag)
    assert d.gps is None
    c = short.config
    for got, want, name in (
        (d.config.dvl_mounting, c.dvl_mounting, "dvl_linkquest"),
        (d.config.ahrs_mounting, c.ahrs_mounting, "imu_adis"),
    ):
        assert got.as_pose() == pytest.approx(want.as_pose(), abs=1e-12)
        assert got.source.endswith(f"sparus -> {name}")
    if keep:
        assert d.config.sonar_mounting.x_m == 0.5
        assert d.config.sonar_mounting.source == "simulator truth"  # the file's
        assert "where it has no [mounting.*] table" in d.calibration
    else:
        assert d.config.sonar_mounting.as_pose() == pytest.approx(c.sonar_mounting.as_pose())
    np.testing.assert_array_equal(d.dvl.valid, short.dvl.valid)
    np.testing.assert_array_equal(d.dvl.v_mps, short.dvl.v_mps)
    np.testing.assert_array_equal(d.beams.intensities, short.beams.intensities)
    a, b = dead_reckoning_trajectory(d), dead_reckoning_trajectory(short)
    np.testing.assert_allclose(a.poses_wTb, b.poses_wTb, rtol=0, atol=1e-9)
    # run prints where the mountings came from and metrics.json records it
    assert main(["run", str(bag), "--backend", "dr", "--out", str(tmp_path / "r"), "--quiet"]) == 0
    assert "from the bag's transforms (base sparus)" in capsys.readouterr().out
    m = json.loads((tmp_path / "r" / "metrics.json").read_text())
    assert "from the bag's transforms (base sparus)" in m["calibration"]


@pytest.mark.parametrize(
    "dvl_type",
    [
        "waterlinked_a50/msg/TransducerReportStamped",
        "waterlinked_dvl/msg/TransducerReportStamped",
        "dvl_msgs/msg/DVLBefore2025",
    ],
)
def test_the_ros2_drivers_ping360_and_water_linked_types(
    dvl_type: str, short: Dataset, tmp_path: Path
) -> None:
    """The ROS 2 Ping360 driver's ``ping360_sonar_msgs/SonarEcho`` (radians in [-pi, pi), a
    range of whole metres, the bin of the sample period it set) and the A50's reports (its
    frame: y to the right) in a ROS 2 sqlite3 bag without definitions: the beams and the DVL
    read back as the run's; ``dvl_msgs/DVL`` of the layout before 2025 too."""
    store = _typestore()
    T = store.types
    n, range_m, c = short.config.sonar.n_bins, 20, 1500
    period = math.floor(2.0 * range_m / (n * c * 25e-9))
    msgs: list[tuple[float, str, object]] = []
    k = 0
    for t, role, msg in _messages(store, short):
        if role == "sonar":
            bearing = float(msg.angle_min)  # type: ignore[attr-defined]
            head = np.angle(np.exp(-1j * bearing))  # the head's own angle (clockwise)
            msg = T["ping360_sonar_msgs/msg/SonarEcho"](
                header=msg.header,  # type: ignore[attr-defined]
                angle=np.float32(head),
                gain=1,
                number_of_samples=n,
                transmit_frequency=740,
                speed_of_sound=c,
                range=range_m,
                intensities=np.asarray(msg.intensities, dtype=np.uint8),  # type: ignore[attr-defined]
            )
        elif role == "dvl":
            v = msg.twist.twist.linear  # type: ignore[attr-defined]
            ok = bool(short.dvl.valid[k])
            k += 1
            h = msg.header  # type: ignore[attr-defined]
            if dvl_type.startswith("dvl_msgs"):
                msg = T[dvl_type](
                    header=h, time=0.0, velocity=T["geometry_msgs/msg/Vector3"](
                        x=v.x, y=-v.y, z=0.0), fom=0.01, altitude=2.0, beams=[],
                    velocity_valid=ok, status=0, form="json_v2",
                )  # fmt: skip
            else:
                pkg = dvl_type.split("/")[0]
                stamp = T["builtin_interfaces/msg/Time"](sec=0, nanosec=0)
                times = {"time_of_validity": 0, "time_of_transmission": 0}
                if pkg == "waterlinked_dvl":
                    times = {"time_of_validity": stamp, "time_of_transmission": stamp}
                report = T[f"{pkg}/msg/TransducerReport"](
                    vx=v.x, vy=-v.y, vz=0.0, fom=0.01, altitude=2.0, transducers=[],
                    velocity_valid=ok, status=0, format="json_v3",
                    **({"type": "velocity"} if pkg == "waterlinked_a50" else {}),
                    time=100.0, covariance=np.zeros(9), **times,
                )  # fmt: skip
                stamped = (
                    {"header": h}
                    if pkg == "waterlinked_dvl"
                    else {"timestamp": int(round(t * 1e9))}
                )
                msg = T[dvl_type](report=report, **stamped)
        msgs.append((t, role, msg))
    topics = {
        "sonar": ("/scan_echo", "ping360_sonar_msgs/msg/SonarEcho"),
        "dvl": ("/dvl", dvl_type),
        "imu": ("/imu", "sensor_msgs/msg/Imu"),
    }
    writer_store = store
    if dvl_type.startswith("dvl_msgs"):  # as the driver named it, in its layout of then
        from rosbags.typesys import Stores, get_types_from_msg, get_typestore

        writer_store = get_typestore(Stores.ROS2_HUMBLE)
        writer_store.register(
            get_types_from_msg(
                CUSTOM_MSG_DEFINITIONS["dvl_msgs/msg/DVLBeam"], "dvl_msgs/msg/DVLBeam"
            )
            | get_types_from_msg(OLDER_DEFINITIONS["dvl_msgs/msg/DVL"][1], "dvl_msgs/msg/DVL")
            | get_types_from_msg(
                CUSTOM_MSG_DEFINITIONS["ping360_sonar_msgs/msg/SonarEcho"],
                "ping360_sonar_msgs/msg/SonarEcho",
            )
        )
        topics["dvl"] = ("/dvl", "dvl_msgs/msg/DVL")
    bag = _write(tmp_path / "b", "sqlite3", writer_store, topics, msgs)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DataWarning)
        d = open_bag(bag)
    assert d.config.sonar.angle_sense == -1  # the head's own angle
    assert math.isclose(d.config.sonar.bin_size_m, c * period * 25e-9 / 2.0, rel_tol=1e-12)
    assert d.config.sonar.bin_size_m < range_m / n  # the truncated period, not range / n
    got = d.config.sonar.bearing_rad(d.beams.transducer_angle_rad)
    want = short.config.sonar.bearing_rad(short.beams.transducer_angle_rad)
    assert np.max(np.abs(np.angle(np.exp(1j * (got - want))))) < 1e-6  # float32 angles
    valid = short.dvl.valid
    np.testing.assert_array_equal(d.dvl.valid, valid)
    np.testing.assert_allclose(d.dvl.v_mps[valid], short.dvl.v_mps[valid], atol=1e-12)
    np.testing.assert_allclose(d.dvl.t, short.dvl.t, atol=1e-6)


def test_a_dvl_msgs_of_the_older_layout_decodes_without_definitions() -> None:
    """A ROS 2 bag without definitions is read with CUSTOM_MSG_DEFINITIONS: a ``dvl_msgs/DVL``
    of the layout before 2025 does not decode with the current one, and is read with the
    older (OLDER_DEFINITIONS)."""
    store = _typestore()
    T = store.types
    older = OLDER_DEFINITIONS["dvl_msgs/msg/DVL"][0]
    h = T["std_msgs/msg/Header"](
        stamp=T["builtin_interfaces/msg/Time"](sec=5, nanosec=0), frame_id="d"
    )
    v = T["geometry_msgs/msg/Vector3"](x=0.5, y=-0.1, z=0.0)
    msg = T[older](header=h, time=100.0, velocity=v, fom=0.01, altitude=2.0, beams=[],
                   velocity_valid=True, status=0, form="json_v2")  # fmt: skip
    raw = store.serialize_cdr(msg, older)

    class Reader:
        def deserialize(self, data: bytes, typ: str) -> object:
            return store.deserialize_cdr(data, typ)

    got = _decode(Path("b"), Reader(), raw, "dvl_msgs/msg/DVL", "/dvl", 0)
    assert float(got.velocity.x) == 0.5 and float(got.altitude) == 2.0
