"""ROS 1 and ROS 2 bags in and out, through ``rosbags`` (no ROS install), streamed.

A bag is a ROS 1 ``.bag`` file, a ROS 2 bag directory (``metadata.yaml`` with ``.db3`` or
``.mcap`` files) or one ``.mcap`` file. Its messages are read one at a time in the bag's order
(never the whole bag in memory; only the decoded arrays of the four roles are kept) and become a
:class:`sonarslam.datasets.source.Dataset` through the same gates as the file readers
(:func:`sonarslam.datasets.arrays.gated_dataset`).

======  ==================================================  ====================================
role    message types                                       what is taken
======  ==================================================  ====================================
sonar   ``sensor_msgs/LaserScan`` (one beam a message)      ``angle_min`` (rad), ``intensities``;
                                                            bin size ``range_max / n``
        ``ping360_sonar/SonarEcho``                         ``angle`` (rad), ``intensities``,
                                                            bin size ``range / number_of_samples``
        ``bluerobotics_sonar_msgs/SonarPing360``            ``angle`` (gradians), ``profile_data``,
                                                            bin size ``range / n``
dvl     ``geometry_msgs/TwistWithCovarianceStamped``,       ``twist.twist.linear`` x, y in the
        ``nav_msgs/Odometry``                               message's frame (the DVL's), m/s;
                                                            a NaN or a negative first variance
                                                            is a row without bottom lock
imu     ``sensor_msgs/Imu``                                 yaw of ``orientation`` (ENU, REP-103),
                                                            ``angular_velocity.z`` (rad/s)
gps     ``sensor_msgs/NavSatFix``                           latitude, longitude; ``status < 0`` is
                                                            no fix. A ruler only, never an input
======  ==================================================  ====================================

Times are the messages' ``header.stamp``. The role of a topic is found by its type when one
topic of the bag fits the role; otherwise ``[topics]`` of ``sonarslam.toml`` (beside a bag
file, or inside a bag directory) or a ``--topics`` file names them (keys ``sonar``, ``dvl``,
``imu``, ``gps``). The custom sonar types are read with the definitions the bag carries (ROS 1,
MCAP), else with :data:`CUSTOM_MSG_DEFINITIONS` (written from the drivers' public ``.msg``).

Bad bags (each a :class:`DataError` naming the bag, the topic and the message's index, or a
counted :class:`DataWarning`): no topic for the sonar, DVL or IMU; a topic of ``[topics]``
missing or of a type that cannot play its role; a type with no definition; a message that
cannot be decoded or a bag cut short; a stamp that jumps against the bag's own clock by more
than :data:`CLOCK_JUMP_S` (an error); a stamp earlier than the one before within that (counted
``fault_<role>_out_of_order``, the messages sorted); a beam of another bin count than the first.
"""

from __future__ import annotations

import math
import tomllib
import warnings
from collections.abc import Iterator
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from sonarslam.datasets.arrays import gated_dataset
from sonarslam.datasets.config import DatasetConfig, load_dataset_config
from sonarslam.datasets.dataset import NEUTRAL_CALIBRATION, Dataset, read_truth
from sonarslam.datasets.errors import DataError, DataWarning
from sonarslam.datasets.geodesy import geodetic_to_local_en, local_en_to_geodetic
from sonarslam.datasets.records import AttitudeSeries, BeamSeries, DvlSeries, GpsSeries

__all__ = [
    "ROLES",
    "ROLE_TYPES",
    "CLOCK_JUMP_S",
    "CUSTOM_MSG_DEFINITIONS",
    "TopicInfo",
    "is_bag",
    "bag_topics",
    "open_bag",
    "write_bag",
]

ROLES = ("sonar", "dvl", "imu", "gps")
#: The message types each role reads (rosbags' names).
ROLE_TYPES: dict[str, tuple[str, ...]] = {
    "sonar": (
        "sensor_msgs/msg/LaserScan",
        "ping360_sonar/msg/SonarEcho",
        "bluerobotics_sonar_msgs/msg/SonarPing360",
    ),
    "dvl": ("geometry_msgs/msg/TwistWithCovarianceStamped", "nav_msgs/msg/Odometry"),
    "imu": ("sensor_msgs/msg/Imu",),
    "gps": ("sensor_msgs/msg/NavSatFix",),
}
REQUIRED_ROLES = ("sonar", "dvl", "imu")
#: A stamp whose step differs from the bag's own (receive) clock's step by more than this (s)
#: is a clock jump: an error, never a trajectory bent by it.
CLOCK_JUMP_S = 1.0
#: The Ping360 drivers' messages, for bags that carry no definitions (ROS 2 sqlite3), written
#: from the drivers' public ``.msg`` files (``ping360_sonar``: CentraleNantesRobotics;
#: ``bluerobotics_sonar_msgs``: itskalvik/bluerobotics_sonar).
CUSTOM_MSG_DEFINITIONS = {
    "ping360_sonar/msg/SonarEcho": (
        "std_msgs/Header header\nfloat32 angle\nuint8 gain\nuint16 number_of_samples\n"
        "uint16 transmit_frequency\nuint16 speed_of_sound\nuint8 range\nuint8[] intensities\n"
    ),
    "bluerobotics_sonar_msgs/msg/SonarPing360": (
        "std_msgs/Header header\nfloat32 distance\nuint8 mode\nuint8 gain_setting\nuint16 angle\n"
        "uint16 transmit_duration\nuint16 sample_period\nuint16 transmit_frequency\n"
        "float32 range\nuint8[] profile_data\n"
    ),
}
GRADIANS_TO_RAD = math.pi / 200.0


def is_bag(path: str | Path) -> bool:
    """A ROS 1 ``.bag``, one ``.mcap`` file, or a ROS 2 bag directory (``metadata.yaml``)."""
    p = Path(path)
    if p.is_file():
        return p.suffix in (".bag", ".mcap")
    return p.is_dir() and (p / "metadata.yaml").is_file()


def _beside(bag: Path, name: str) -> Path | None:
    """A file that goes with the bag: inside a bag directory, else beside the bag file."""
    found = (bag if bag.is_dir() else bag.parent) / name
    return found if found.is_file() else None


def _typestore() -> Any:
    """ROS 2 Humble's types plus the Ping360 drivers' (:data:`CUSTOM_MSG_DEFINITIONS`)."""
    from rosbags.typesys import (  # lazy: only bags load rosbags
        Stores,
        get_types_from_msg,
        get_typestore,
    )

    store = get_typestore(Stores.ROS2_HUMBLE)
    types: dict[str, Any] = {}
    for name, text in CUSTOM_MSG_DEFINITIONS.items():
        types.update(get_types_from_msg(text, name))
    store.register(types)
    return store


@dataclass(frozen=True)
class TopicInfo:
    """A topic of a bag: its type, message count, rate (Hz over its span) and role ("" none)."""

    topic: str
    msgtype: str
    count: int
    rate_hz: float
    role: str


class _Reader:
    """An open bag (``rosbags.highlevel.AnyReader``) whose errors are :class:`DataError`."""

    def __init__(self, bag: Path) -> None:
        from rosbags.highlevel import AnyReader, AnyReaderError  # lazy: only bags load rosbags

        self.bag = bag
        paths = [bag]
        try:
            self.reader = AnyReader(paths, default_typestore=_typestore())
            self.reader.open()
        except (AnyReaderError, OSError, ValueError, KeyError) as exc:
            raise DataError(bag, None, f"not a readable ROS bag: {_one_line(exc)}") from None
        except Exception as exc:  # rosbags' own reader errors (a bag cut short, a bad index)
            raise DataError(bag, None, f"not a readable ROS bag: {_one_line(exc)}") from None

    def __enter__(self) -> _Reader:
        return self

    def __exit__(self, *exc: object) -> None:
        try:
            self.reader.close()
        except Exception:  # closing a broken bag: the error that matters is already raised
            pass


def _one_line(exc: BaseException) -> str:
    return " ".join(str(exc).split()) or type(exc).__name__


def _topics_table(bag: Path, topics_file: str | Path | None) -> tuple[dict[str, str], Path | None]:
    """``[topics]`` of ``--topics``, else of the bag's ``sonarslam.toml``; role -> topic."""
    path = Path(topics_file) if topics_file is not None else _beside(bag, "sonarslam.toml")
    if path is None:
        return {}, None
    try:
        data = tomllib.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError) as exc:
        raise DataError(path, None, f"cannot read [topics]: {_one_line(exc)}") from None
    table = data.get("topics", {})
    if not isinstance(table, dict):
        raise DataError(path, None, "[topics] must be a table of role = topic")
    unknown = sorted(set(table) - set(ROLES))
    if unknown:
        raise DataError(path, None, f"[topics]: unknown role(s) {unknown}; allowed: {list(ROLES)}")
    for role, topic in table.items():
        if not isinstance(topic, str) or not topic:
            raise DataError(path, None, f"[topics] {role} must be a topic name, got {topic!r}")
    return dict(table), path


def _roles(
    bag: Path, types: dict[str, str], table: dict[str, str], table_path: Path | None
) -> dict[str, str]:
    """Role -> topic: ``[topics]`` where given (checked), else the one topic of a fitting type."""
    out: dict[str, str] = {}
    for role in ROLES:
        if role in table:
            topic = table[role]
            if topic not in types:
                raise DataError(
                    table_path or bag,
                    None,
                    f"[topics] {role} = {topic!r}: no such topic in {bag} (its topics:"
                    f" {sorted(types)})",
                )
            if types[topic] not in ROLE_TYPES[role]:
                raise DataError(
                    bag,
                    None,
                    f"topic {topic} is {types[topic]}, which cannot be the {role}"
                    f" ({', '.join(ROLE_TYPES[role])})",
                )
            out[role] = topic
            continue
        fits = sorted(t for t, ty in types.items() if ty in ROLE_TYPES[role])
        if len(fits) == 1:
            out[role] = fits[0]
        elif len(fits) > 1:
            raise DataError(
                bag,
                None,
                f"{len(fits)} topics could be the {role} ({', '.join(fits)}): name one under"
                f' [topics] in sonarslam.toml or a --topics file ({role} = "{fits[0]}")',
            )
    return out


def bag_topics(bag: str | Path, topics_file: str | Path | None = None) -> list[TopicInfo]:
    """Every topic of a bag with its type, count, rate and role (``sonarslam info BAG``)."""
    p = Path(bag)
    table, table_path = _topics_table(p, topics_file)
    with _Reader(p) as r:
        info = r.reader.topics
        types = {t: i.msgtype or "" for t, i in info.items()}
        try:
            roles = {t: role for role, t in _roles(p, types, table, table_path).items()}
        except DataError:
            roles = {}
        out = []
        span_s = max((r.reader.end_time - r.reader.start_time) * 1e-9, 0.0)
        for topic, i in sorted(info.items()):
            rate = i.msgcount / span_s if span_s > 0 else 0.0
            out.append(TopicInfo(topic, types[topic], int(i.msgcount), rate, roles.get(topic, "")))
    return out


def _stamp(msg: Any) -> float:
    s = msg.header.stamp
    return float(s.sec) + 1e-9 * float(s.nanosec)


@dataclass
class _Column:
    """One role's decoded messages, in the bag's order, with their stamp checks."""

    role: str
    topic: str
    t: list[float] = field(default_factory=list)
    rows: list[Any] = field(default_factory=list)
    last_t: float = -math.inf
    last_log_s: float = -math.inf
    out_of_order: int = 0

    def add(self, bag: Path, index: int, t: float, log_s: float, row: Any) -> None:
        if self.t:
            jump = (t - self.last_t) - (log_s - self.last_log_s)
            if abs(jump) > CLOCK_JUMP_S:
                raise DataError(
                    bag,
                    None,
                    f"topic {self.topic} ({self.role}) message {index}: its stamp jumps"
                    f" {t - self.last_t:+.3f} s while the bag's clock moves"
                    f" {log_s - self.last_log_s:+.3f} s (a clock jump beyond {CLOCK_JUMP_S:g} s)",
                )
            if t < self.last_t:
                self.out_of_order += 1
        self.t.append(t)
        self.rows.append(row)
        self.last_t, self.last_log_s = t, log_s

    def order(self, bag: Path) -> np.ndarray:
        """The indices that sort the stamps (a warning counts the messages out of order)."""
        t = np.asarray(self.t, dtype=np.float64)
        if self.out_of_order:
            warnings.warn(
                f"{bag}: topic {self.topic} ({self.role}): {self.out_of_order} message(s) stamped"
                " earlier than the one before, sorted by stamp",
                DataWarning,
                stacklevel=3,
            )
        return np.argsort(t, kind="stable")


def _sonar_row(msgtype: str, msg: Any) -> tuple[float, float, np.ndarray]:
    """(transducer angle rad, bin size m, intensities uint8) of one beam message."""
    if msgtype == "sensor_msgs/msg/LaserScan":
        values = np.asarray(msg.intensities, dtype=np.float64)
        bins = np.clip(np.rint(values), 0, 255).astype(np.uint8)
        return float(msg.angle_min), float(msg.range_max) / max(bins.size, 1), bins
    if msgtype == "ping360_sonar/msg/SonarEcho":
        bins = np.asarray(msg.intensities, dtype=np.uint8)
        return float(msg.angle), float(msg.range) / max(bins.size, 1), bins
    bins = np.asarray(msg.profile_data, dtype=np.uint8)
    return float(msg.angle) * GRADIANS_TO_RAD, float(msg.range) / max(bins.size, 1), bins


def _dvl_row(msgtype: str, msg: Any) -> tuple[float, float, bool]:
    tw = msg.twist
    vx, vy = float(tw.twist.linear.x), float(tw.twist.linear.y)
    var = float(tw.covariance[0])
    ok = math.isfinite(vx) and math.isfinite(vy) and not var < 0.0
    return (vx if ok else 0.0), (vy if ok else 0.0), ok


def _imu_row(msg: Any) -> tuple[float, float]:
    q = msg.orientation
    yaw = math.atan2(2.0 * (q.w * q.z + q.x * q.y), 1.0 - 2.0 * (q.y * q.y + q.z * q.z))
    return yaw, float(msg.angular_velocity.z)


def _gps_row(msg: Any) -> tuple[float, float, bool]:
    lat, lon = float(msg.latitude), float(msg.longitude)
    fix = int(msg.status.status) >= 0 and math.isfinite(lat) and math.isfinite(lon)
    return lat, lon, fix and not (lat == 0.0 and lon == 0.0)


def _read_columns(bag: Path, roles: dict[str, str]) -> tuple[dict[str, _Column], dict[str, str]]:
    """One pass over the bag's messages of the roles' topics."""
    columns = {role: _Column(role, topic) for role, topic in roles.items()}
    by_topic = {topic: role for role, topic in roles.items()}
    with _Reader(bag) as r:
        reader = r.reader
        conns = [c for c in reader.connections if c.topic in by_topic]
        types = {c.topic: c.msgtype for c in conns}
        counts = dict.fromkeys(by_topic, 0)
        topic = ""
        try:
            for conn, log_ns, raw in reader.messages(connections=conns):
                topic = conn.topic
                role = by_topic[topic]
                index = counts[topic]
                counts[topic] += 1
                try:
                    msg = reader.deserialize(raw, conn.msgtype)
                except Exception as exc:
                    raise DataError(
                        bag,
                        None,
                        f"topic {topic} ({conn.msgtype}) message {index}: cannot be decoded:"
                        f" {_one_line(exc)}",
                    ) from None
                if role == "sonar":
                    row: Any = _sonar_row(conn.msgtype, msg)
                elif role == "dvl":
                    row = _dvl_row(conn.msgtype, msg)
                elif role == "imu":
                    row = _imu_row(msg)
                else:
                    row = _gps_row(msg)
                t = _stamp(msg)
                if not math.isfinite(t) or t <= 0.0:
                    raise DataError(
                        bag, None, f"topic {topic} message {index}: stamp {t!r} is not a time"
                    )
                columns[role].add(bag, index, t, log_ns * 1e-9, row)
        except DataError:
            raise
        except Exception as exc:  # a bag cut short, a bad chunk: where the reading stopped
            where = f" after message {counts.get(topic, 0) - 1} of {topic}" if topic else ""
            raise DataError(
                bag, None, f"the bag cannot be read on{where}: {_one_line(exc)}"
            ) from None
    return columns, types


def open_bag(
    bag: str | Path,
    config_override: str | Path | None = None,
    topics_file: str | Path | None = None,
) -> Dataset:
    """Read a bag into a gated :class:`Dataset` (module docstring).

    The configuration is the bag's ``sonarslam.toml`` (inside a bag directory or beside a bag
    file) or else neutral (a :class:`DataWarning`, :data:`NEUTRAL_CALIBRATION`); the head's
    ``n_bins`` and ``bin_size_m`` are the messages' own (a ``sonarslam.toml`` that says
    otherwise is a :class:`DataError`); ``config_override`` keys go on top.
    """
    p = Path(bag)
    if not is_bag(p):
        raise DataError(p, None, "not a ROS bag (.bag, .mcap, or a directory with metadata.yaml)")
    table, table_path = _topics_table(p, topics_file)
    with _Reader(p) as r:
        types = {t: i.msgtype or "" for t, i in r.reader.topics.items()}
    roles = _roles(p, types, table, table_path)
    missing = [role for role in REQUIRED_ROLES if role not in roles]
    if missing:
        listing = ", ".join(f"{t} ({ty})" for t, ty in sorted(types.items())) or "none"
        raise DataError(
            p,
            None,
            f"no topic for the {', '.join(missing)} (types: "
            + "; ".join(f"{m}: {', '.join(ROLE_TYPES[m])}" for m in missing)
            + f"); the bag's topics: {listing}",
        )
    columns, _ = _read_columns(p, roles)
    for role in REQUIRED_ROLES:
        if not columns[role].t:
            raise DataError(p, None, f"topic {roles[role]} ({role}) has no message")
    toml = _beside(p, "sonarslam.toml")
    if toml is not None:
        config, calibration = load_dataset_config(toml), str(toml)
    else:
        config, calibration = DatasetConfig(), NEUTRAL_CALIBRATION
        if config_override is None:
            warnings.warn(f"{p}: {NEUTRAL_CALIBRATION}", DataWarning, stacklevel=2)
    if config_override is not None:
        config = load_dataset_config(config_override, base=config)
        calibration = f"{calibration}; over it {config_override}"
    beams = _beams(p, columns["sonar"], config)
    sonar_head = replace(config.sonar, n_bins=beams[1], bin_size_m=beams[2])
    if (
        toml is not None
        and _file_sets_head(toml)
        and (config.sonar.n_bins != beams[1] or not math.isclose(config.sonar.bin_size_m, beams[2]))
    ):
        raise DataError(
            toml,
            None,
            f"[sonar] n_bins {config.sonar.n_bins}, bin_size_m {config.sonar.bin_size_m:g}: the"
            f" bag's beams have {beams[1]} bins of {beams[2]:g} m (leave them out; the bag's win)",
        )
    config = replace(config, sonar=sonar_head)
    series = beams[0]
    if config.sonar_time_offset_s:
        series = series.shifted(config.sonar_time_offset_s)
    dvl, att = _dvl(p, columns["dvl"]), _imu(p, columns["imu"])
    gps = _gps(p, columns["gps"]) if "gps" in columns and columns["gps"].t else None
    counts = {f"{role}_out_of_order": c.out_of_order for role, c in columns.items()}
    truth = _beside(p, "truth.json")
    name = p.stem if p.is_file() else p.name
    d = gated_dataset(
        name,
        p,
        config,
        series,
        dvl,
        att,
        gps,
        calibration,
        truth=read_truth(truth) if truth is not None else None,
    )
    d.report.counts.update(counts)
    return d


def _file_sets_head(toml: Path) -> bool:
    try:
        sonar = tomllib.loads(toml.read_text(encoding="utf-8")).get("sonar", {})
    except (OSError, tomllib.TOMLDecodeError):
        return False
    return isinstance(sonar, dict) and ("n_bins" in sonar or "bin_size_m" in sonar)


def _beams(bag: Path, col: _Column, config: DatasetConfig) -> tuple[BeamSeries, int, float]:
    order = col.order(bag)
    first = col.rows[0]
    n_bins, bin_m = int(first[2].size), float(first[1])
    if n_bins == 0 or not bin_m > 0.0:
        raise DataError(
            bag, None, f"topic {col.topic} message 0: a beam of {n_bins} bins over {bin_m:g} m"
        )
    data = np.empty((len(col.rows), n_bins), dtype=np.uint8)
    angles = np.empty(len(col.rows))
    for k, i in enumerate(order):
        angle, size_m, bins = col.rows[i]
        if bins.size != n_bins or not math.isclose(size_m, bin_m, rel_tol=1e-4):
            raise DataError(
                bag,
                None,
                f"topic {col.topic} message {int(i)}: a beam of {bins.size} bins of {size_m:g} m"
                f" after {n_bins} bins of {bin_m:g} m (the head's range changed: one run a"
                " range)",
            )
        data[k] = bins
        angles[k] = angle
    col.rows.clear()  # the beams now live in ``data`` only
    t = np.asarray(col.t, dtype=np.float64)[order]
    return BeamSeries(t, angles, data, False), n_bins, bin_m


def _dvl(bag: Path, col: _Column) -> DvlSeries:
    order = col.order(bag)
    rows = np.asarray(col.rows, dtype=np.float64)[order]
    t = np.asarray(col.t, dtype=np.float64)[order]
    return DvlSeries(t, rows[:, :2].copy(), rows[:, 2] > 0.5, np.full(t.size, np.nan), bag)


def _imu(bag: Path, col: _Column) -> AttitudeSeries:
    order = col.order(bag)
    rows = np.asarray(col.rows, dtype=np.float64)[order]
    t = np.asarray(col.t, dtype=np.float64)[order]
    return AttitudeSeries(t, rows[:, 0].copy(), rows[:, 1].copy(), bag)


def _gps(bag: Path, col: _Column) -> GpsSeries:
    order = col.order(bag)
    rows = np.asarray(col.rows, dtype=np.float64)[order]
    t = np.asarray(col.t, dtype=np.float64)[order]
    fix = rows[:, 2] > 0.5
    if not fix.any():
        raise DataError(bag, None, f"topic {col.topic} (gps): no message with a fix")
    first = int(np.flatnonzero(fix)[0])
    lat0, lon0 = float(rows[first, 0]), float(rows[first, 1])
    lat = np.where(fix, rows[:, 0], lat0)
    lon = np.where(fix, rows[:, 1], lon0)
    en = geodetic_to_local_en(lat, lon, lat0, lon0)
    return GpsSeries(t, en, (lat0, lon0), fix, bag)


# -- writing (the simulator's round trips) -----------------------------------------------------

#: The topics :func:`write_bag` writes.
WRITTEN_TOPICS = {
    "sonar": "/sonar/scan",
    "dvl": "/dvl/twist",
    "imu": "/imu/data",
    "gps": "/gps/fix",
}
BAG_KINDS = ("ros1", "mcap", "sqlite3")


def _stamp_of(store: Any, t_s: float) -> Any:
    sec = int(math.floor(t_s))
    nanosec = int(round((t_s - sec) * 1e9))
    if nanosec >= 1_000_000_000:
        sec, nanosec = sec + 1, nanosec - 1_000_000_000
    return store.types["builtin_interfaces/msg/Time"](sec=sec, nanosec=nanosec)


def _messages(store: Any, d: Dataset) -> Iterator[tuple[float, str, Any]]:
    """(time, role, message) of a dataset in time order: the inverse of :func:`open_bag`."""
    T = store.types
    header = T["std_msgs/msg/Header"]
    vec = T["geometry_msgs/msg/Vector3"]
    n = d.config.sonar.n_bins
    range_m = n * d.config.sonar.bin_size_m
    ranges = (np.arange(1, n + 1) * d.config.sonar.bin_size_m).astype(np.float32)
    cov36 = np.zeros(36)
    cov9 = np.zeros(9)
    beams = d.beams.shifted(-d.config.sonar_time_offset_s)

    def head(t: float, frame: str) -> Any:
        return header(stamp=_stamp_of(store, t), frame_id=frame)

    items: list[tuple[float, int, str, int]] = []
    items += [(float(t), 0, "imu", i) for i, t in enumerate(d.attitude.t)]
    items += [(float(t), 1, "dvl", i) for i, t in enumerate(d.dvl.t)]
    if d.gps is not None:
        items += [(float(t), 2, "gps", i) for i, t in enumerate(d.gps.t)]
    items += [(float(t), 3, "sonar", i) for i, t in enumerate(beams.t_s)]
    items.sort()
    lat_lon = None
    if d.gps is not None:
        lat, lon = local_en_to_geodetic(
            d.gps.en_m[:, 0], d.gps.en_m[:, 1], *d.gps.origin_lat_lon_deg
        )
        lat_lon = np.column_stack([lat, lon])
    for t, _, role, i in items:
        if role == "imu":
            yaw = float(d.attitude.yaw_rad[i])
            q = T["geometry_msgs/msg/Quaternion"](
                x=0.0, y=0.0, z=math.sin(yaw / 2), w=math.cos(yaw / 2)
            )
            w = vec(x=0.0, y=0.0, z=float(d.attitude.yaw_rate_rad_per_s[i]))
            msg = T["sensor_msgs/msg/Imu"](
                header=head(t, "imu"),
                orientation=q,
                orientation_covariance=cov9,
                angular_velocity=w,
                angular_velocity_covariance=cov9,
                linear_acceleration=vec(x=0.0, y=0.0, z=0.0),
                linear_acceleration_covariance=cov9,
            )
        elif role == "dvl":
            ok = bool(d.dvl.valid[i])
            v = d.dvl.v_mps[i]
            cov = cov36.copy()
            cov[0] = 0.0 if ok else -1.0
            twist = T["geometry_msgs/msg/Twist"](
                linear=vec(x=float(v[0]), y=float(v[1]), z=0.0), angular=vec(x=0.0, y=0.0, z=0.0)
            )
            msg = T["geometry_msgs/msg/TwistWithCovarianceStamped"](
                header=head(t, "dvl"),
                twist=T["geometry_msgs/msg/TwistWithCovariance"](twist=twist, covariance=cov),
            )
        elif role == "gps":
            assert lat_lon is not None
            status = T["sensor_msgs/msg/NavSatStatus"](status=0, service=1)
            msg = T["sensor_msgs/msg/NavSatFix"](
                header=head(t, "gps"),
                status=status,
                latitude=float(lat_lon[i, 0]),
                longitude=float(lat_lon[i, 1]),
                altitude=0.0,
                position_covariance=cov9,
                position_covariance_type=0,
            )
        else:
            angle = float(beams.transducer_angle_rad[i])
            msg = T["sensor_msgs/msg/LaserScan"](
                header=head(t, "sonar"),
                angle_min=angle,
                angle_max=angle,
                angle_increment=0.0,
                time_increment=0.0,
                scan_time=0.0,
                range_min=0.0,
                range_max=range_m,
                ranges=ranges,
                intensities=beams.intensities[i].astype(np.float32),
            )
        yield t, role, msg


def write_bag(d: Dataset, path: str | Path, kind: str) -> Path:
    """Write a dataset's beams (``LaserScan``), DVL (``TwistWithCovarianceStamped``), AHRS
    (``Imu``) and GPS (``NavSatFix``) as a bag: ``kind`` ``"ros1"`` (``path`` a ``.bag`` file),
    ``"mcap"`` or ``"sqlite3"`` (``path`` a ROS 2 bag directory). Each message's receive time
    is its stamp. Returns ``path``."""
    from rosbags.rosbag1 import Writer as Writer1  # lazy: only bags load rosbags
    from rosbags.rosbag2 import StoragePlugin  # lazy: only bags load rosbags
    from rosbags.rosbag2 import Writer as Writer2  # lazy: only bags load rosbags

    if kind not in BAG_KINDS:
        raise ValueError(f"bag kind must be one of {BAG_KINDS}, got {kind!r}")
    p = Path(path)
    store = _typestore()
    types = {
        "sonar": "sensor_msgs/msg/LaserScan",
        "dvl": "geometry_msgs/msg/TwistWithCovarianceStamped",
        "imu": "sensor_msgs/msg/Imu",
        "gps": "sensor_msgs/msg/NavSatFix",
    }
    roles = [r for r in ROLES if r != "gps" or d.gps is not None]
    if kind == "ros1":
        with Writer1(p) as w1:
            conns = {
                r: w1.add_connection(WRITTEN_TOPICS[r], types[r], typestore=store) for r in roles
            }
            for t, role, msg in _messages(store, d):
                raw = store.serialize_ros1(msg, types[role])
                w1.write(conns[role], int(round(t * 1e9)), raw)
        return p
    plugin = StoragePlugin.MCAP if kind == "mcap" else StoragePlugin.SQLITE3
    with Writer2(p, version=9, storage_plugin=plugin) as w2:
        conns = {r: w2.add_connection(WRITTEN_TOPICS[r], types[r], typestore=store) for r in roles}
        for t, role, msg in _messages(store, d):
            raw = store.serialize_cdr(msg, types[role])
            w2.write(conns[role], int(round(t * 1e9)), raw)
    return p
