"""Reading a bag in memory that does not grow with its length (issue 30's target).

The gates now work through a series in blocks and in place (:mod:`sonarslam.datasets.gates`);
here they give exactly (bit for bit) what the whole-array code they replace gave, written out
below as the reference, on series with every fault the gates look for and blocks small enough
that every pass crosses them. And a ROS 1 bag four times as long costs, above its output arrays,
no more memory (tracemalloc's peak, within a stated tolerance).
"""

from __future__ import annotations

import math
import tracemalloc
import warnings
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest

from sonarslam.datasets import gates as g
from sonarslam.datasets.config import GateConfig
from sonarslam.datasets.errors import DataWarning
from sonarslam.datasets.records import AttitudeSeries, DvlSeries

# -- the whole-array gates as they were (the reference) ------------------------------------------


def _ref_find_gaps(t: np.ndarray, gates: GateConfig) -> tuple[float, np.ndarray]:
    dt = np.diff(t)
    positive = dt[dt > 0.0]
    period = float(np.median(positive)) if positive.size else 0.0
    threshold = max(gates.gap_periods * period, gates.min_gap_s)
    i = np.flatnonzero(dt > threshold)
    return threshold, np.column_stack([t[i], t[i + 1]]) if i.size else np.zeros((0, 2))


def _ref_dvl(d: DvlSeries, gates: GateConfig) -> tuple[tuple[np.ndarray, ...], list[int]]:
    keep = ~np.concatenate([[False], np.diff(d.t) == 0.0])
    t, v, valid, heading = d.t[keep], d.v_mps[keep], d.valid[keep], d.heading_rad[keep]
    with np.errstate(over="ignore"):
        fast = valid & ~(np.hypot(v[:, 0], v[:, 1]) <= gates.dvl_max_speed_mps)
    return (t, v, valid & ~fast, heading), [int((~keep).sum()), int(fast.sum())]


def _ref_attitude(a: AttitudeSeries, gates: GateConfig) -> tuple[tuple[np.ndarray, ...], list[int]]:
    repeat = np.concatenate([[False], np.diff(a.t) == 0.0])
    spike = ~repeat & ~(np.abs(a.yaw_rate_rad_per_s) <= math.radians(gates.ahrs_max_rate_deg_per_s))
    keep = ~(repeat | spike)
    t, yaw, rate = a.t[keep], a.yaw_rad[keep], a.yaw_rate_rad_per_s[keep]
    gyro = np.concatenate([[0.0], np.cumsum(0.5 * (rate[1:] + rate[:-1]) * np.diff(t))])
    tol0, drift = (
        math.radians(gates.ahrs_max_jump_deg),
        math.radians(gates.ahrs_jump_drift_deg_per_s),
    )
    good = np.ones(t.size, dtype=bool)
    ref_t, ref_y, ref_g = float(t[0]), float(yaw[0]), float(gyro[0])
    for k in range(1, t.size):
        miss = (yaw[k] - ref_y - (gyro[k] - ref_g) + math.pi) % (2.0 * math.pi) - math.pi
        if abs(miss) <= tol0 + drift * (t[k] - ref_t):
            ref_t, ref_y, ref_g = float(t[k]), float(yaw[k]), float(gyro[k])
        else:
            good[k] = False
    counts = [int(repeat.sum()), int(spike.sum()), int((~good).sum())]
    return (t[good], yaw[good], rate[good]), counts


def _times(rng: np.random.Generator, n: int, period_s: float) -> np.ndarray:
    """Sample times with jitter, repeated stamps and a few gaps (non-decreasing)."""
    dt = period_s * rng.uniform(0.8, 1.2, n)
    dt[rng.random(n) < 0.03] = 0.0  # repeated stamps
    dt[rng.random(n) < 0.004] *= 40.0  # gaps
    dt = np.round(dt, 3)  # a logger's millisecond stamps: many steps tie (the median's ties)
    return 1.7e9 + np.cumsum(dt)


@pytest.fixture
def small_blocks(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(g, "BLOCK", 37)
    monkeypatch.setattr(g, "ATTITUDE_BLOCK", 37)


@pytest.mark.parametrize("seed", range(6))
def test_the_median_step_and_the_gaps_are_the_whole_arrays(seed: int, small_blocks: None) -> None:
    rng = np.random.default_rng(seed)
    n = [0, 1, 2, 501, 1000, 1777][seed]
    t = _times(rng, n, 0.2)
    mask = rng.random(n) < 0.8
    gates = GateConfig()
    for src, m in ((t, None), (t[mask], None), (t, mask)):
        tt = src if m is None else src[m]
        positive = np.diff(tt)[np.diff(tt) > 0.0]
        want = float(np.median(positive)) if positive.size else 0.0
        assert g._median_step(src, m) == want  # exact, not close
        threshold, spans = _ref_find_gaps(tt, gates)
        got = g.find_gaps(src, gates, m)
        assert got.threshold_s == threshold
        assert np.array_equal(got.spans_s, spans)


@pytest.mark.parametrize("seed", range(4))
def test_the_gates_in_blocks_and_in_place_are_the_whole_array_gates(
    seed: int, small_blocks: None
) -> None:
    rng = np.random.default_rng(100 + seed)
    gates = GateConfig()
    n = 1500
    t = _times(rng, n, 0.2)
    v = rng.normal(0.0, 0.5, (n, 2))
    v[rng.random(n) < 0.02] *= 20.0  # speed spikes
    valid = rng.random(n) < 0.95
    dvl = DvlSeries(t, v, valid, rng.uniform(-3, 3, n), Path("dvl"))
    want, counts = _ref_dvl(dvl, gates)
    report = g.SensorReport()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DataWarning)
        got = g.gate_dvl(
            DvlSeries(t.copy(), v.copy(), valid.copy(), dvl.heading_rad.copy(), Path("dvl")),
            gates,
            report,
        )
    for a, b in zip((got.t, got.v_mps, got.valid, got.heading_rad), want, strict=True):
        assert np.array_equal(a, b)
    assert [report.counts["dvl_repeated_stamps"], report.counts["dvl_speed_spikes"]] == counts
    assert counts[0] > 0 and counts[1] > 0  # the faults were there to gate
    assert np.array_equal(report.gaps["dvl"].spans_s, _ref_find_gaps(want[0][want[2]], gates)[1])

    ta = _times(rng, 4 * n, 0.05)
    rate = rng.normal(0.0, 0.05, ta.size)
    rate[rng.random(ta.size) < 0.01] = 50.0  # rate spikes
    yaw = np.cumsum(rate) * 0.05
    yaw[rng.random(ta.size) < 0.01] += 1.0  # heading jumps
    yaw = (yaw + np.pi) % (2 * np.pi) - np.pi
    att = AttitudeSeries(ta, yaw, rate, Path("ahrs"))
    want_a, counts_a = _ref_attitude(att, gates)
    report = g.SensorReport()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DataWarning)
        got_a = g.gate_attitude(
            AttitudeSeries(ta.copy(), yaw.copy(), rate.copy(), Path("ahrs")), gates, report
        )
    for a, b in zip((got_a.t, got_a.yaw_rad, got_a.yaw_rate_rad_per_s), want_a, strict=True):
        assert np.array_equal(a, b)
    kinds = ("ahrs_repeated_stamps", "ahrs_rate_spikes", "ahrs_heading_jumps")
    assert [report.counts[k] for k in kinds] == counts_a
    assert min(counts_a) > 0
    assert np.array_equal(report.gaps["ahrs"].spans_s, _ref_find_gaps(want_a[0], gates)[1])


# -- memory against the bag's length -------------------------------------------------------------

#: A bag four times as long may cost this much more above its output arrays (bytes): 10 kB
#: measured; rosbags' own reader, with its index of every message, cost 1.1 MB more for the
#: 7,200 more messages.
GROWTH_TOL_BYTES = 200_000


def _write_bag(path: Path, seconds: float) -> Path:
    """A Ping360-like rig's ROS 1 bag (beams of 200 bins at 25 Hz, DVL 5 Hz, IMU 50 Hz)."""
    from rosbags.rosbag1 import Writer

    from sonarslam.datasets.rosbag import _stamp_of, _typestore

    store = _typestore()
    T = store.types
    vec = T["geometry_msgs/msg/Vector3"]
    z9, z36 = np.zeros(9), np.zeros(36)
    ranges = np.arange(1, 201, dtype=np.float32) * 0.1
    rng = np.random.default_rng(0)
    events = sorted(
        (1.7e9 + k / hz, role)
        for role, hz in (("imu", 50.0), ("dvl", 5.0), ("sonar", 25.0))
        for k in range(int(seconds * hz))
    )
    types = {
        "sonar": "sensor_msgs/msg/LaserScan",
        "dvl": "geometry_msgs/msg/TwistWithCovarianceStamped",
        "imu": "sensor_msgs/msg/Imu",
    }
    msgs: dict[str, Callable[[float, object], object]] = {
        "imu": lambda t, h: T["sensor_msgs/msg/Imu"](
            header=h,
            orientation=T["geometry_msgs/msg/Quaternion"](
                x=0.0, y=0.0, z=math.sin(0.005 * (t - 1.7e9)), w=math.cos(0.005 * (t - 1.7e9))
            ),
            orientation_covariance=z9,
            angular_velocity=vec(x=0.0, y=0.0, z=0.01),
            angular_velocity_covariance=z9,
            linear_acceleration=vec(x=0.0, y=0.0, z=0.0),
            linear_acceleration_covariance=z9,
        ),
        "dvl": lambda t, h: T["geometry_msgs/msg/TwistWithCovarianceStamped"](
            header=h,
            twist=T["geometry_msgs/msg/TwistWithCovariance"](
                twist=T["geometry_msgs/msg/Twist"](
                    linear=vec(x=0.5, y=0.0, z=0.0), angular=vec(x=0.0, y=0.0, z=0.0)
                ),
                covariance=z36,
            ),
        ),
        "sonar": lambda t, h: T["sensor_msgs/msg/LaserScan"](
            header=h,
            angle_min=(t * 0.7) % 6.0,
            angle_max=0.0,
            angle_increment=0.0,
            time_increment=0.0,
            scan_time=0.0,
            range_min=0.0,
            range_max=20.0,
            ranges=ranges,
            intensities=rng.integers(0, 60, 200).astype(np.float32),
        ),
    }
    w = Writer(path)
    w.chunk_threshold = 1 << 16  # chunks of 64 kB: the chunk in memory is not the bag's length
    with w:
        conns = {r: w.add_connection(f"/{r}", ty, typestore=store) for r, ty in types.items()}
        for t, role in events:
            h = T["std_msgs/msg/Header"](stamp=_stamp_of(store, t), frame_id=role)
            raw = store.serialize_ros1(msgs[role](t, h), types[role])
            w.write(conns[role], int(round(t * 1e9)), raw)
    return path


def _overhead(path: Path) -> tuple[int, int]:
    """(tracemalloc's peak while reading, above the memory before and the dataset's arrays;
    the dataset's arrays), bytes."""
    from sonarslam.datasets.rosbag import open_bag

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DataWarning)
        open_bag(path)  # rosbags loaded and its types built before the measurement
        tracemalloc.start()
        try:
            before = tracemalloc.get_traced_memory()[0]
            d = open_bag(path)
            peak = tracemalloc.get_traced_memory()[1]
        finally:
            tracemalloc.stop()
    b, v, a = d.beams, d.dvl, d.attitude
    arrays = [b.intensities, b.t_s, b.transducer_angle_rad, v.t, v.v_mps, v.valid, v.heading_rad]
    arrays += [a.t, a.yaw_rad, a.yaw_rate_rad_per_s]
    outputs = sum(x.base.nbytes if x.base is not None else x.nbytes for x in arrays)
    return peak - before - outputs, outputs


def test_a_bag_four_times_as_long_costs_no_more_above_its_arrays(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    # the gates' blocks (8192 samples) made shorter than the short bag's series, so that a
    # block's temporaries are the same in both (as in a bag of minutes)
    monkeypatch.setattr(g, "BLOCK", 256)
    monkeypatch.setattr(g, "ATTITUDE_BLOCK", 256)
    short, short_out = _overhead(_write_bag(tmp_path / "short.bag", 30.0))
    long, long_out = _overhead(_write_bag(tmp_path / "long.bag", 120.0))
    assert long_out > 3.5 * short_out  # the outputs do grow with the bag
    assert long - short < GROWTH_TOL_BYTES, (short, long)


def test_an_index_counting_more_messages_than_memory_is_an_error() -> None:
    """The arrays are preallocated from the bag's count: a damaged count is one line naming
    the bag and the topic, never a MemoryError."""
    from sonarslam.datasets.errors import DataError
    from sonarslam.datasets.rosbag import _Column

    with pytest.raises(DataError, match=r"x\.bag: topic /imu: the bag's index counts 10{15}"):
        _Column(Path("x.bag"), "imu", "/imu", 10**15)
