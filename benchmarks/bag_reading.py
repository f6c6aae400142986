"""Reading a ROS bag: speed against real time and peak memory against the bag's length.

Writes a ROS 1 bag (or ROS 2 MCAP) of a Ping360-like rig at realistic rates (sonar
``LaserScan`` beams of 1200 bins at 25 Hz, DVL 5 Hz, IMU 50 Hz, GPS 1 Hz; a vehicle turning
slowly at 0.5 m/s) for each length asked, then reads each in a fresh process
(:func:`sonarslam.datasets.rosbag.open_bag`, the gates included) and reports its wall time, the
real-time factor, the process's peak resident memory (``VmHWM``, which ``exec`` resets: the
``ru_maxrss`` of a child keeps its parent's peak across ``exec``), the output arrays and the
reader's overhead::

    overhead = VmHWM after reading - VmHWM before reading - the dataset's arrays

The dataset's arrays are every array the returned dataset holds (beams: intensities, times,
angles; DVL: times, velocities, lock, heading; AHRS: times, yaw, rate; GPS: times, East-North),
each counted as the buffer it is a view of: necessarily as long as the bag. "Before reading" is
after Python, numpy and the project are imported, before ``rosbags`` is (its import and its
typestore are in the overhead, a constant). The overhead is what must not grow with the bag's
length. Each row also gives the machine's load (1-minute average) when it was measured::

    taskset -c 1 .venv/bin/python benchmarks/bag_reading.py --minutes 5 20 60 120 --kind ros1 \
        --dir /tmp/bag_bench

Target (issue 30): >= 50x real time on one core; an overhead that does not grow with length.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import resource
import subprocess
import sys
import tempfile
import time
import warnings
from pathlib import Path

import numpy as np

SONAR_HZ, DVL_HZ, IMU_HZ, GPS_HZ = 25.0, 5.0, 50.0, 1.0
N_BINS, BIN_M = 1200, 0.05
T0_S = 1_700_000_000.0


def write(path: Path, minutes: float, kind: str) -> Path:
    """A synthetic bag of ``minutes``: the vehicle's messages in time order."""
    from rosbags.rosbag1 import Writer as Writer1
    from rosbags.rosbag2 import StoragePlugin
    from rosbags.rosbag2 import Writer as Writer2

    from sonarslam.datasets.rosbag import _stamp_of, _typestore

    store = _typestore()
    T = store.types
    rng = np.random.default_rng(0)
    duration = 60.0 * minutes
    events: list[tuple[float, str]] = []
    for role, hz in (("imu", IMU_HZ), ("dvl", DVL_HZ), ("gps", GPS_HZ), ("sonar", SONAR_HZ)):
        events += [(T0_S + k / hz, role) for k in range(int(duration * hz))]
    events.sort()
    types = {
        "sonar": "sensor_msgs/msg/LaserScan",
        "dvl": "geometry_msgs/msg/TwistWithCovarianceStamped",
        "imu": "sensor_msgs/msg/Imu",
        "gps": "sensor_msgs/msg/NavSatFix",
    }
    vec = T["geometry_msgs/msg/Vector3"]
    ranges = (np.arange(1, N_BINS + 1) * BIN_M).astype(np.float32)
    z9, z36 = np.zeros(9), np.zeros(36)
    if kind == "ros1":
        writer: object = Writer1(path)
        serialize = store.serialize_ros1
    else:
        plugin = StoragePlugin.MCAP if kind == "mcap" else StoragePlugin.SQLITE3
        writer = Writer2(path, version=9, storage_plugin=plugin)
        serialize = store.serialize_cdr
    with writer as w:  # type: ignore[attr-defined]
        conns = {r: w.add_connection(f"/{r}", ty, typestore=store) for r, ty in types.items()}
        for t, role in events:
            h = T["std_msgs/msg/Header"](stamp=_stamp_of(store, t), frame_id=role)
            yaw = 0.01 * (t - T0_S)
            if role == "imu":
                q = T["geometry_msgs/msg/Quaternion"](
                    x=0.0, y=0.0, z=math.sin(yaw / 2), w=math.cos(yaw / 2)
                )
                msg = T["sensor_msgs/msg/Imu"](
                    header=h,
                    orientation=q,
                    orientation_covariance=z9,
                    angular_velocity=vec(x=0.0, y=0.0, z=0.01),
                    angular_velocity_covariance=z9,
                    linear_acceleration=vec(x=0.0, y=0.0, z=0.0),
                    linear_acceleration_covariance=z9,
                )
            elif role == "dvl":
                tw = T["geometry_msgs/msg/Twist"](
                    linear=vec(x=0.5, y=0.0, z=0.0), angular=vec(x=0.0, y=0.0, z=0.0)
                )
                msg = T["geometry_msgs/msg/TwistWithCovarianceStamped"](
                    header=h,
                    twist=T["geometry_msgs/msg/TwistWithCovariance"](twist=tw, covariance=z36),
                )
            elif role == "gps":
                msg = T["sensor_msgs/msg/NavSatFix"](
                    header=h,
                    status=T["sensor_msgs/msg/NavSatStatus"](status=0, service=1),
                    latitude=42.2 + 1e-6 * (t - T0_S),
                    longitude=3.1,
                    altitude=0.0,
                    position_covariance=z9,
                    position_covariance_type=0,
                )
            else:
                angle = (t - T0_S) * SONAR_HZ * 0.9 * math.pi / 200.0 % (2 * math.pi)
                bins = rng.integers(0, 60, N_BINS).astype(np.float32)
                msg = T["sensor_msgs/msg/LaserScan"](
                    header=h,
                    angle_min=angle,
                    angle_max=angle,
                    angle_increment=0.0,
                    time_increment=0.0,
                    scan_time=0.0,
                    range_min=0.0,
                    range_max=N_BINS * BIN_M,
                    ranges=ranges,
                    intensities=bins,
                )
            w.write(conns[role], int(round(t * 1e9)), serialize(msg, types[role]))
    return path


def _hwm_mb() -> float:
    """This process's peak resident memory (MB) since its ``exec``."""
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith("VmHWM:"):
            return float(line.split()[1]) / 1024.0
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0  # not Linux


def read(path: Path) -> dict[str, float]:
    """Read one bag in this process: wall time, data span, peak RSS, the output arrays."""
    from sonarslam.datasets.errors import DataWarning
    from sonarslam.datasets.rosbag import open_bag

    before = _hwm_mb()
    t0 = time.perf_counter()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DataWarning)
        d = open_bag(path)
    wall = time.perf_counter() - t0
    span = float(d.attitude.t[-1] - d.attitude.t[0])
    peak = _hwm_mb()
    b, v, a, g = d.beams, d.dvl, d.attitude, d.gps
    arrays = [b.intensities, b.t_s, b.transducer_angle_rad, v.t, v.v_mps, v.valid, v.heading_rad]
    arrays += [a.t, a.yaw_rad, a.yaw_rate_rad_per_s] + ([g.t, g.en_m] if g is not None else [])
    # each as the buffer it is a view of (the readers' preallocated arrays), once
    held = {
        id(x.base if x.base is not None else x): x.base if x.base is not None else x for x in arrays
    }
    outputs = sum(x.nbytes for x in held.values()) / 2**20
    return {
        "wall_s": wall,
        "data_s": span,
        "realtime_factor": span / wall,
        "peak_rss_mb": peak,
        "rss_before_read_mb": before,
        "beams_mb": b.intensities.nbytes / 2**20,
        "outputs_mb": outputs,
        "overhead_mb": peak - before - outputs,
        "beams": len(b),
        "load_1min": os.getloadavg()[0],
    }


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--minutes", type=float, nargs="+", default=[5.0, 20.0])
    ap.add_argument("--kind", choices=("ros1", "mcap", "sqlite3"), default="ros1")
    ap.add_argument("--dir", help="write the bags here and keep them (reused when present)")
    ap.add_argument("--read", help=argparse.SUPPRESS)  # the child process: read this bag
    args = ap.parse_args()
    if args.read:
        print(json.dumps(read(Path(args.read))))
        return 0
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(args.dir) if args.dir else Path(tmp)
        folder.mkdir(parents=True, exist_ok=True)
        for minutes in args.minutes:
            name = f"bench_{minutes:g}min_{args.kind}" + (".bag" if args.kind == "ros1" else "")
            path = folder / name
            if not (args.dir and path.exists()):
                write(path, minutes, args.kind)
            out = subprocess.run(
                [sys.executable, __file__, "--read", str(path)],
                check=True,
                capture_output=True,
                text=True,
            ).stdout
            row = {
                "minutes": minutes,
                "kind": args.kind,
                "bag_mb": _size_mb(path),
                **json.loads(out),
            }
            rows.append(row)
            print(json.dumps(row))
    return 0


def _size_mb(path: Path) -> float:
    files = [path] if path.is_file() else list(path.rglob("*"))
    return sum(f.stat().st_size for f in files if f.is_file()) / 2**20


if __name__ == "__main__":
    raise SystemExit(main())
