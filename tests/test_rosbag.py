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

from sonarslam.datasets.errors import DataWarning
from sonarslam.datasets.rosbag import bag_topics, is_bag, write_bag
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
