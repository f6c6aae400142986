"""ROS bags in and out (issue 30, items 1, 5 and 6): the simulator's run written as a ROS 1 bag
and ROS 2 MCAP and sqlite3 bags reads back as the directory reads, and a bad bag is one line."""

from __future__ import annotations

import json
import shutil
import warnings
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest

from sonarslam.datasets.errors import DataError, DataWarning
from sonarslam.datasets.rosbag import (
    CLOCK_JUMP_S,
    _messages,
    _stamp_of,
    _typestore,
    bag_topics,
    is_bag,
    open_bag,
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
    for name in ("sonarslam.toml", "truth.json"):
        shutil.copy(harbour / name, beside / name)
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
    assert d.config == layout.config
    np.testing.assert_array_equal(d.beams.intensities, layout.beams.intensities)
    np.testing.assert_array_equal(d.beams.t_s, layout.beams.t_s)  # ns stamps of these times
    np.testing.assert_allclose(
        d.beams.transducer_angle_rad, layout.beams.transducer_angle_rad, rtol=0, atol=ANGLE_TOL_RAD
    )
    np.testing.assert_array_equal(d.dvl.v_mps, layout.dvl.v_mps)
    np.testing.assert_array_equal(d.dvl.valid, layout.dvl.valid)
    np.testing.assert_array_equal(d.attitude.t, layout.attitude.t)
    yaw_miss = np.angle(np.exp(1j * (d.attitude.yaw_rad - layout.attitude.yaw_rad)))
    assert np.max(np.abs(yaw_miss)) < 1e-12
    assert d.gps is not None and layout.gps is not None
    np.testing.assert_allclose(d.gps.en_m, layout.gps.en_m, rtol=0, atol=GPS_TOL_M)
    assert d.report.counts == {
        **layout.report.counts,
        **{f"{r}_out_of_order": 0 for r in ("sonar", "dvl", "imu", "gps")},
    }
    # the same trajectory: dead reckoning reads no beams, so to the last bit
    a, b = dead_reckoning_trajectory(d), dead_reckoning_trajectory(layout)
    np.testing.assert_array_equal(a.t_s, b.t_s)
    np.testing.assert_allclose(a.poses_wTb, b.poses_wTb, rtol=0, atol=1e-9)


def test_info_lists_the_roles_and_run_takes_a_bag(
    bags: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    roles = {t.topic: (t.msgtype, t.role, t.count) for t in bag_topics(bags["ros1"])}
    assert roles["/sonar/scan"][:2] == ("sensor_msgs/msg/LaserScan", "sonar")
    assert roles["/gps/fix"][1] == "gps" and roles["/imu/data"][2] == 3000
    assert main(["info", str(bags["mcap"])]) == 0
    out = capsys.readouterr().out
    assert "/dvl/twist" in out and "geometry_msgs/msg/TwistWithCovarianceStamped" in out
    assert main(["run", str(bags["sqlite3"]), "--out", str(tmp_path / "r"), "--quiet"]) == 0
    m = json.loads((tmp_path / "r" / "metrics.json").read_text())
    assert m["calibration"].endswith("sonarslam.toml") and m["evaluation"] == "gps and truth"


def test_simulate_writes_a_bag(tmp_path: Path) -> None:
    out = tmp_path / "sim"
    assert main(["simulate", "pool", "--duration", "30", "--out", str(out), "--bag", "mcap"]) == 0
    assert (out / "metadata.yaml").is_file() and (out / "sonarslam.toml").is_file()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DataWarning)
        d = open_dataset(out)
    assert len(d.beams) > 100 and d.truth is not None


def _write_ros1(d: Dataset, path: Path, change: Callable[[str, int, float], float]) -> Path:
    """``d`` as a ROS 1 bag whose header stamps are ``change(role, index, t)`` (the receive
    times stay ``t``): out-of-order stamps and clock jumps."""
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


@pytest.mark.parametrize("kind", ["ros1", "sqlite3"])
def test_ping360_messages_give_beams_in_radians_and_metres(
    kind: str, short: Dataset, tmp_path: Path
) -> None:
    """SonarPing360 (gradians, profile_data, range) in a ROS 2 sqlite3 bag, whose types come
    from CUSTOM_MSG_DEFINITIONS; SonarEcho (radians) in a ROS 1 bag, which carries its own."""
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
            angle=grad * np.pi / 200.0,
            gain=1,
            number_of_samples=n,
            transmit_frequency=750,
            speed_of_sound=1500,
            range=range_m,
            intensities=bins,
        )

    def serialize(msg: object, ty: str) -> bytes:
        return store.serialize_ros1(msg, ty) if kind == "ros1" else store.serialize_cdr(msg, ty)

    path = tmp_path / ("p.bag" if kind == "ros1" else "p")
    w = (
        Writer1(path)
        if kind == "ros1"
        else Writer2(path, version=9, storage_plugin=StoragePlugin.SQLITE3)
    )
    with w:
        conns = {r: w.add_connection(f"/{r}", ty, typestore=store) for r, ty in types.items()}
        for t, role, msg in _messages(store, short):
            if role in conns:
                out = sonar(msg) if role == "sonar" else msg
                w.write(conns[role], int(round(t * 1e9)), serialize(out, types[role]))
    with pytest.warns(DataWarning, match="neutral"):
        d = open_bag(path)
    np.testing.assert_allclose(
        d.beams.transducer_angle_rad, np.array(grads) * np.pi / 200.0, atol=1e-6
    )
    np.testing.assert_array_equal(d.beams.intensities, short.beams.intensities)
    assert d.config.sonar.n_bins == n and d.config.sonar.bin_size_m == pytest.approx(range_m / n)
