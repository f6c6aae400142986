"""ROS 1 and ROS 2 bags in and out, through ``rosbags`` (no ROS install), streamed.

A bag is a ROS 1 ``.bag`` file, a ROS 2 bag directory (``metadata.yaml`` with ``.db3`` or
``.mcap`` files) or one ``.mcap`` file. Its messages are read one at a time in the bag's order
(a ROS 1 bag chunk by chunk, :class:`sonarslam.datasets.ros1bag.Ros1Bag`; a ROS 2 bag through
``rosbags.highlevel.AnyReader``), never the whole bag in memory: each field of a role's rows goes
into an array preallocated from the bag's count of its topic, and those arrays are the series.
:func:`read_roles` reads any of the roles (the Ping360's navigation bag: the DVL, the IMU and the
GPS); :func:`open_bag` reads the four and makes them a
:class:`sonarslam.datasets.source.Dataset` through the same gates as the file readers
(:func:`sonarslam.datasets.arrays.gated_dataset`).

======  ==================================================  ====================================
role    message types                                       what is taken
======  ==================================================  ====================================
sonar   ``sensor_msgs/LaserScan`` (one beam a message)      ``angle_min`` (rad, counter-clockwise
                                                            about the frame's z: REP-103, so
                                                            ``angle_sense = +1`` by default),
                                                            ``intensities``; bin size
                                                            ``range_max / n``
        ``ping360_sonar/SonarEcho``                         ``angle`` (rad), ``intensities``,
                                                            bin size ``range / number_of_samples``
        ``ping360_sonar_msgs/SonarEcho`` (the ROS 2         ``angle`` (rad, the head's own, in
        driver's)                                           [-pi, pi)), ``intensities``, the bin
                                                            size of the sample period the driver
                                                            set (:func:`ping360_driver_bin_m`)
        ``bluerobotics_sonar_msgs/SonarPing360``            ``angle`` (gradians), ``profile_data``,
                                                            bin size ``range / n``
dvl     ``geometry_msgs/TwistWithCovarianceStamped``,       ``twist.twist.linear`` x, y in the
        ``nav_msgs/Odometry``                               message's frame (the DVL's), m/s;
                                                            a NaN or a negative first variance
                                                            is a row without bottom lock
        Water Linked ``dvl_msgs/DVL``,                      ``velocity`` x and minus y (the A50's
        ``waterlinked_a50_ros_driver/DVL``,                 frame has y to the right),
        ``TransducerReportStamped`` (``waterlinked_dvl``,   ``velocity_valid``; ``fom`` said
        ``waterlinked_a50``: ``report.vx``, ``vy``)         beside ``[noise] dvl_sigma_mps``
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
``fault_<role>_out_of_order``, the messages sorted); a beam of another bin count than the first;
a beam angle read as radians beyond 2 pi or not finite (the ROS 1 ``ping360_sonar`` node's
``SonarEcho.angle`` in gradians 0-399, a ``LaserScan`` in degrees) or a ``SonarPing360`` angle
outside 0-399 gradians, at its first such message.
"""

from __future__ import annotations

import math
import tomllib
import warnings
from collections.abc import Iterator
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from sonarslam.datasets.arrays import gated_dataset
from sonarslam.datasets.config import DatasetConfig, load_dataset_config
from sonarslam.datasets.dataset import (
    NEUTRAL_CALIBRATION,
    Dataset,
    mounting_tables,
    neutral_warning,
    read_truth,
    warn_assumed_mountings,
)
from sonarslam.datasets.errors import DataError, DataWarning
from sonarslam.datasets.gates import check_heading_sense
from sonarslam.datasets.geodesy import geodetic_to_local_en, local_en_to_geodetic
from sonarslam.datasets.records import (
    STEP_TOLERANCE,
    AttitudeSeries,
    BeamSeries,
    DvlSeries,
    GpsSeries,
)
from sonarslam.datasets.ros1bag import Ros1Bag
from sonarslam.datasets.toml import toml_file_line
from sonarslam.sonar.beam import Mounting, SonarHead

__all__ = [
    "bag_config",
    "ROLES",
    "ROLE_TYPES",
    "CLOCK_JUMP_S",
    "CUSTOM_MSG_DEFINITIONS",
    "TopicInfo",
    "is_bag",
    "bag_topics",
    "open_bag",
    "read_roles",
    "BagRoles",
    "write_bag",
    "transform_msg",
    "ping360_driver_bin_m",
    "OLDER_DEFINITIONS",
    "TRANSDUCER_REPORT_TYPES",
    "WATERLINKED_DVL_TYPES",
]

ROLES = ("sonar", "dvl", "imu", "gps")
#: The message types each role reads (rosbags' names).
ROLE_TYPES: dict[str, tuple[str, ...]] = {
    "sonar": (
        "sensor_msgs/msg/LaserScan",
        "ping360_sonar/msg/SonarEcho",
        "ping360_sonar_msgs/msg/SonarEcho",
        "bluerobotics_sonar_msgs/msg/SonarPing360",
        "marine_acoustic_msgs/msg/ProjectedSonarImage",
    ),
    "dvl": (
        "geometry_msgs/msg/TwistWithCovarianceStamped",
        "nav_msgs/msg/Odometry",
        "dvl_msgs/msg/DVL",
        "waterlinked_a50_ros_driver/msg/DVL",
        "waterlinked_dvl/msg/TransducerReportStamped",
        "waterlinked_a50/msg/TransducerReportStamped",
        "marine_acoustic_msgs/msg/Dvl",
        "cirs_girona_cala_viuda/msg/LinkquestDvl",
    ),
    "imu": ("sensor_msgs/msg/Imu",),
    "gps": ("sensor_msgs/msg/NavSatFix",),
}
#: Water Linked's DVL message: ROS 2 (``dvl_msgs``) and ROS 1 (``waterlinked_a50_ros_driver``).
#: Like every Water Linked driver they copy the A50's report: its velocity in the DVL's frame
#: x forward, y right (starboard), z down (docs.waterlinked.com, "Axes"), read here with y
#: negated to the project's y left.
WATERLINKED_DVL_TYPES = ("dvl_msgs/msg/DVL", "waterlinked_a50_ros_driver/msg/DVL")
#: The A50's report wrapped whole (``report.vx``...): ROS 1 ``waterlinked_dvl`` (a header) and
#: its ROS 2 port ``waterlinked_a50`` (no header: ``timestamp``, ns of the ROS clock).
TRANSDUCER_REPORT_TYPES = (
    "waterlinked_dvl/msg/TransducerReportStamped",
    "waterlinked_a50/msg/TransducerReportStamped",
)
REQUIRED_ROLES = ("sonar", "dvl", "imu")
#: A stamp whose step differs from the bag's own (receive) clock's step by more than this (s)
#: is a clock jump: an error, never a trajectory bent by it.
CLOCK_JUMP_S = 1.0
#: Custom messages, for bags that carry no definitions (ROS 2 sqlite3), written from the drivers'
#: public ``.msg`` files: ``ping360_sonar`` (CentraleNantesRobotics, its ROS 1 node) and
#: ``ping360_sonar_msgs`` (its ROS 2 driver, ``ping360_sonar_msgs/msg/SonarEcho.msg`` at
#: fa53b8f: the same fields); ``bluerobotics_sonar_msgs`` (itskalvik/bluerobotics_sonar); Water
#: Linked's DVL (waterlinked/dvl-a50-ros-driver, ``msg/DVL.msg`` and ``msg/DVLBeam.msg`` at
#: e86b038, ROS 1; the ROS 2 ``dvl_msgs`` of paagutie/dvl_msgs at 555525e, which added
#: ``covariance``, ``time_of_validity`` and ``time_of_transmission`` in 2025: a bag of the
#: older layout without definitions is read with :data:`OLDER_DEFINITIONS`); the A50's
#: ``TransducerReportStamped`` (uri-ocean-robotics/waterlinked_dvl at 2aaecc2, ROS 1, and its
#: ROS 2 port timzarhansen/waterlinked_a50_dvl_ros2 at 4533199, whose ``Transducer.msg`` could
#: not be read: taken as the ROS 1 one's fields); ``marine_acoustic_msgs`` 2.0.2 (apl-ocean-engineering/marine_msgs at
#: 88e39b6: ``Dvl``, ``ProjectedSonarImage``, ``PingInfo``, ``SonarImageData``); the caves data
#: set's DVL (``cirs_girona_cala_viuda/msg/LinkquestDvl``: PickNikRobotics/cirs_girona_cala_viuda
#: at 366029a, the ROS 2 port of the data set, whose field names are the ROS 1 original's in
#: lower case: ``velocityInst`` -> ``velocityinst``; a ROS 1 bag carries its own).
CUSTOM_MSG_DEFINITIONS = {
    "ping360_sonar/msg/SonarEcho": (
        "std_msgs/Header header\nfloat32 angle\nuint8 gain\nuint16 number_of_samples\n"
        "uint16 transmit_frequency\nuint16 speed_of_sound\nuint8 range\nuint8[] intensities\n"
    ),
    "ping360_sonar_msgs/msg/SonarEcho": (
        "std_msgs/Header header\nfloat32 angle\nuint8 gain\nuint16 number_of_samples\n"
        "uint16 transmit_frequency\nuint16 speed_of_sound\nuint8 range\nuint8[] intensities\n"
    ),
    "waterlinked_dvl/msg/Transducer": (
        "int32 id\nfloat64 velocity\nfloat64 distance\nfloat64 rssi\nfloat64 nsd\nbool beam_valid\n"
    ),
    "waterlinked_dvl/msg/TransducerReport": (
        "float64 vx\nfloat64 vy\nfloat64 vz\nfloat64 fom\nfloat64 altitude\n"
        "waterlinked_dvl/Transducer[] transducers\nbool velocity_valid\nint32 status\n"
        "string format\nfloat64 time\nfloat64[9] covariance\nbuiltin_interfaces/Time"
        " time_of_validity\nbuiltin_interfaces/Time time_of_transmission\n"
    ),
    "waterlinked_dvl/msg/TransducerReportStamped": (
        "std_msgs/Header header\nwaterlinked_dvl/TransducerReport report\n"
    ),
    "waterlinked_a50/msg/Transducer": (
        "int32 id\nfloat64 velocity\nfloat64 distance\nfloat64 rssi\nfloat64 nsd\nbool beam_valid\n"
    ),
    "waterlinked_a50/msg/TransducerReport": (
        "float64 vx\nfloat64 vy\nfloat64 vz\nfloat64 fom\nfloat64 altitude\n"
        "waterlinked_a50/Transducer[] transducers\nbool velocity_valid\nint32 status\n"
        "string format\nstring type\nfloat64 time\nfloat64[9] covariance\n"
        "uint64 time_of_validity\nuint64 time_of_transmission\n"
    ),
    "waterlinked_a50/msg/TransducerReportStamped": (
        "uint64 timestamp\nwaterlinked_a50/TransducerReport report\n"
    ),
    "bluerobotics_sonar_msgs/msg/SonarPing360": (
        "std_msgs/Header header\nfloat32 distance\nuint8 mode\nuint8 gain_setting\nuint16 angle\n"
        "uint16 transmit_duration\nuint16 sample_period\nuint16 transmit_frequency\n"
        "float32 range\nuint8[] profile_data\n"
    ),
    "dvl_msgs/msg/DVLBeam": (
        "int64 id\nfloat64 velocity\nfloat64 distance\nfloat64 rssi\nfloat64 nsd\nbool valid\n"
    ),
    "dvl_msgs/msg/DVL": (
        "std_msgs/Header header\nfloat64 time\ngeometry_msgs/Vector3 velocity\nfloat64 fom\n"
        "float64[] covariance\nfloat64 altitude\ndvl_msgs/DVLBeam[] beams\n"
        "bool velocity_valid\nint64 status\nint64 time_of_validity\n"
        "int64 time_of_transmission\nstring form\n"
    ),
    "marine_acoustic_msgs/msg/Dvl": (
        "uint8 DVL_MODE_BOTTOM=1\nuint8 DVL_MODE_WATER=2\nuint8 DVL_TYPE_PISTON=0\n"
        "uint8 DVL_TYPE_PHASED_ARRAY=1\nstd_msgs/Header header\nuint8 velocity_mode\n"
        "uint8 dvl_type\ngeometry_msgs/Vector3 velocity\nfloat64[9] velocity_covar\n"
        "float64 altitude\nfloat64 course_gnd\nfloat64 speed_gnd\nuint8 num_good_beams\n"
        "float32 sound_speed\nbool beam_ranges_valid\nbool beam_velocities_valid\n"
        "geometry_msgs/Vector3[4] beam_unit_vec\nfloat64[4] range\nfloat32[4] range_covar\n"
        "float32[4] beam_quality\nfloat32[4] beam_velocity\nfloat32[4] beam_velocity_covar\n"
    ),
    "marine_acoustic_msgs/msg/PingInfo": (
        "float32 frequency\nfloat32 sound_speed\nfloat32[] tx_beamwidths\nfloat32[] rx_beamwidths\n"
    ),
    "marine_acoustic_msgs/msg/SonarImageData": (
        "bool is_bigendian\nuint32 DTYPE_UINT8=0\nuint32 DTYPE_INT8=1\nuint32 DTYPE_UINT16=2\n"
        "uint32 DTYPE_INT16=3\nuint32 DTYPE_UINT32=4\nuint32 DTYPE_INT32=5\n"
        "uint32 DTYPE_UINT64=6\nuint32 DTYPE_INT64=7\nuint32 DTYPE_FLOAT32=8\n"
        "uint32 DTYPE_FLOAT64=9\nuint32 dtype\nuint32 beam_count\nuint8[] data\n"
    ),
    "marine_acoustic_msgs/msg/ProjectedSonarImage": (
        "std_msgs/Header header\nmarine_acoustic_msgs/PingInfo ping_info\n"
        "geometry_msgs/Vector3[] beam_directions\nfloat32[] ranges\n"
        "marine_acoustic_msgs/SonarImageData image\n"
    ),
    "cirs_girona_cala_viuda/msg/LinkquestDvl": (
        "std_msgs/Header header\nstring errcode\nint32[4] datagood\nfloat64[4] altitudebeam\n"
        "float64[4] bottomvelocitybeam\nfloat64[4] watervelocitybeam\n"
        "float64[4] watervelocitycredit\nfloat64[3] velocityinst\nint32 velocityinstflag\n"
        "float64[3] velocityearth\nint32 velocityearthflag\nfloat64[3] watervelocityinst\n"
        "int32 watervelocityinstflag\nfloat64[3] watervelocityearth\n"
        "int32 watervelocityearthflag\nfloat64 roll\nfloat64 pitch\nfloat64 heading\n"
        "float64 altitude\nfloat64 temperature\nfloat64 pressure\nfloat64 salinity\n"
        "float64 soundspeed\nstring rawdata\n"
    ),
}
#: Older layouts of a custom type under another name, tried when a message does not decode
#: with the current one (a ROS 2 sqlite3 bag carries no definitions): ``dvl_msgs/DVL`` before
#: its 2025 fields.
OLDER_DEFINITIONS = {
    "dvl_msgs/msg/DVL": (
        "dvl_msgs/msg/DVLBefore2025",
        "std_msgs/Header header\nfloat64 time\ngeometry_msgs/Vector3 velocity\nfloat64 fom\n"
        "float64 altitude\ndvl_msgs/DVLBeam[] beams\nbool velocity_valid\nint64 status\n"
        "string form\n",
    ),
}
#: Named sets of topics (``--topics NAME`` or ``preset = "NAME"`` under ``[topics]``), each
#: with the base frame of its transforms. ``caves``: the Girona underwater caves data set
#: (Mallios et al., IJRR 2017; a Sparus II AUV): its topics and types as listed by the ROS 2
#: port's ``data/metadata.yaml`` (PickNikRobotics/cirs_girona_cala_viuda), its frames as the
#: port's rviz tree shows them (``world -> sparus -> sonar_micron, dvl_linkquest, imu_adis,
#: ...``, the sensor offsets on ``/tf``, no ``/tf_static``). The Micron (horizontal MSIS) is
#: ``/sonar_micron_ros`` (``/sonar_seaking_ros`` is the vertical profiler); the ADIS16480 IMU
#: ``/imu_adis_ros`` (``/imu_xsens_mti_ros`` the second IMU); the LinkQuest DVL
#: ``/dvl_linkquest`` (``/odometry`` is the vehicle's own dead reckoning, not a DVL).
TOPIC_PRESETS: dict[str, dict[str, str]] = {
    "caves": {
        "sonar": "/sonar_micron_ros",
        "dvl": "/dvl_linkquest",
        "imu": "/imu_adis_ros",
        "base_frame": "sparus",
    },
}
#: The keys of ``[topics]`` besides the roles.
TOPIC_KEYS = ("preset", "base_frame")
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


#: ``tf2_msgs/TFMessage``, which rosbags' ROS 1 (Noetic) store leaves out.
_TF_MESSAGE = "geometry_msgs/TransformStamped[] transforms\n"


def _typestore(ros1: bool = False) -> Any:
    """ROS 2 Humble's types plus the Ping360 drivers' (:data:`CUSTOM_MSG_DEFINITIONS`); with
    ``ros1`` ROS 1 Noetic's instead (its ``Header`` has ``seq``; its definitions and MD5 sums
    are those a ROS 1 tool expects: ``LaserScan`` ``90c7ef2d...``), plus the same custom
    types and ``tf2_msgs/TFMessage``."""
    from rosbags.typesys import (  # lazy: only bags load rosbags
        Stores,
        get_types_from_msg,
        get_typestore,
    )

    store = get_typestore(Stores.ROS1_NOETIC if ros1 else Stores.ROS2_HUMBLE)
    types: dict[str, Any] = {}
    for name, text in CUSTOM_MSG_DEFINITIONS.items():
        types.update(get_types_from_msg(text, name))
    for older, text in OLDER_DEFINITIONS.values():
        types.update(get_types_from_msg(text, older))
    if "tf2_msgs/msg/TFMessage" not in store.types:
        types.update(get_types_from_msg(_TF_MESSAGE, "tf2_msgs/msg/TFMessage"))
    store.register(types)
    return store


def _header(store: Any, t_s: float, frame: str) -> Any:
    """A ``std_msgs/Header`` at ``t_s`` (Unix s) in ``frame`` (``seq`` 0 in ROS 1's)."""
    header = store.types["std_msgs/msg/Header"]
    seq = {"seq": 0} if "seq" in header.__dataclass_fields__ else {}
    return header(**seq, stamp=_stamp_of(store, t_s), frame_id=frame)


@dataclass(frozen=True)
class TopicInfo:
    """A topic of a bag: its type, message count, rate (Hz over its span) and role ("" none)."""

    topic: str
    msgtype: str
    count: int
    rate_hz: float
    role: str


class _Reader:
    """An open bag whose errors are :class:`DataError`: a ROS 1 ``.bag`` through
    :class:`sonarslam.datasets.ros1bag.Ros1Bag` (chunk by chunk), a ROS 2 bag through
    ``rosbags.highlevel.AnyReader``."""

    def __init__(self, bag: Path) -> None:
        from rosbags.highlevel import AnyReader, AnyReaderError  # lazy: only bags load rosbags

        self.bag = bag
        paths = [bag]
        # a FIFO, a device or a directory in place of a bag's file would block or read without
        # end inside rosbags' (and sqlite's) own calls, beyond any signal: refused first
        files = (
            [bag] if not bag.is_dir() else [f for f in bag.iterdir() if f.name != "metadata.yaml"]
        )
        for f in files:
            if f.suffix in (".bag", ".mcap", ".db3") and not f.is_file():
                raise DataError(f, None, "not a regular file (a bag's data must be one)")
        try:
            self.reader: Any
            if bag.is_file() and bag.suffix == ".bag":  # chunk by chunk, no index of messages
                self.reader = Ros1Bag(bag)
            else:
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
    """``[topics]`` of ``--topics`` (a file, or a name of :data:`TOPIC_PRESETS`), else of the
    bag's ``sonarslam.toml``; role (or ``base_frame``) -> name. A ``preset`` key brings the
    preset's names, the file's own keys going over them."""
    if topics_file is not None and str(topics_file) in TOPIC_PRESETS:
        return dict(TOPIC_PRESETS[str(topics_file)]), None
    path = Path(topics_file) if topics_file is not None else _beside(bag, "sonarslam.toml")
    if path is None:
        return {}, None
    try:
        data = tomllib.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError) as exc:
        raise DataError(path, None, f"cannot read [topics]: {_one_line(exc)}") from None
    if topics_file is not None and "topics" not in data:  # a file given for its [topics]
        raise DataError(
            path,
            None,
            f"no [topics] table (its tables: {sorted(data)}): write [topics] role = topic",
        )
    table = data.get("topics", {})
    if not isinstance(table, dict):
        raise DataError(path, None, "[topics] must be a table of role = topic")
    unknown = sorted(set(table) - set(ROLES) - set(TOPIC_KEYS))
    if unknown:
        raise DataError(
            path,
            None,
            f"[topics]: unknown key(s) {unknown}; allowed: {[*ROLES, *TOPIC_KEYS]}",
        )
    for role, topic in table.items():
        if not isinstance(topic, str) or not topic:
            raise DataError(path, None, f"[topics] {role} must be a name, got {topic!r}")
    out: dict[str, str] = {}
    if "preset" in table:
        if table["preset"] not in TOPIC_PRESETS:
            raise DataError(
                path,
                None,
                f"[topics] preset = {table['preset']!r}: no such preset ({', '.join(TOPIC_PRESETS)})",
            )
        out.update(TOPIC_PRESETS[table.pop("preset")])
    out.update(table)
    return out, path


def _with_preset(types: dict[str, str], table: dict[str, str]) -> dict[str, str]:
    """``table``, or without one the preset the bag's topics are (:func:`_preset_of`)."""
    preset = _preset_of(types) if not table else None
    return dict(TOPIC_PRESETS[preset]) if preset is not None else table


def _preset_of(types: dict[str, str]) -> str | None:
    """The preset whose every role topic the bag has, with a type that fits the role."""
    for name, preset in TOPIC_PRESETS.items():
        if all(types.get(preset[role], "") in ROLE_TYPES[role] for role in ROLES if role in preset):
            return name
    return None


def _roles(
    bag: Path,
    types: dict[str, str],
    table: dict[str, str],
    table_path: Path | None,
    wanted: tuple[str, ...] = ROLES,
) -> dict[str, str]:
    """Role -> topic of the ``wanted`` roles: ``[topics]`` where given (checked), else the one
    topic of a fitting type."""
    out: dict[str, str] = {}
    table = _with_preset(types, table)
    for role in wanted:
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
    if not hasattr(msg, "header"):  # waterlinked_a50's report: a ns stamp of the ROS clock
        return float(msg.timestamp) * 1e-9
    s = msg.header.stamp
    return float(s.sec) + 1e-9 * float(s.nanosec)


class _Column:
    """One role's decoded messages, in the bag's order, with their stamp checks.

    Each field of a row goes into its own numpy array, preallocated from the bag's own message
    count of the topic (grown by half when a bag's index undercounts), and the role's series
    are views of those arrays (:meth:`arrays`): reading keeps the output arrays and a constant
    overhead, never a Python object per message nor a second copy of a field."""

    def __init__(self, bag: Path, role: str, topic: str, count: int) -> None:
        self.role, self.topic = role, topic
        self.n = 0
        self.capacity = max(int(count), 16)
        try:
            self.t = np.empty(self.capacity, dtype=np.float64)
            self.fields = {
                name: np.empty((self.capacity, *shape), dtype=dtype)
                for name, shape, dtype in ROW_FIELDS[role]
            }
        except (MemoryError, ValueError):
            raise DataError(
                bag, None, f"topic {topic}: the bag's index counts {count} messages, beyond memory"
            ) from None
        self.bins: np.ndarray | None = None  # sonar: (capacity, n_bins) uint8
        self.bin_m = math.nan  # sonar: the first beam's bin size (m)
        self.frame = ""
        self.last_t = -math.inf
        self.last_log_s = -math.inf
        self.out_of_order = 0
        self.repeated = 0
        self.first_fault: dict[str, int] = {}  # "out_of_order", "repeated" -> message index
        self.sorted = False  # the messages out of order have been sorted (by :meth:`arrays`)

    def _grow(self) -> None:
        self.capacity += max(self.capacity // 2, 16)
        self.t = np.resize(self.t, self.capacity)
        for name, x in self.fields.items():
            self.fields[name] = np.resize(x, (self.capacity, *x.shape[1:]))
        if self.bins is not None:
            self.bins = np.resize(self.bins, (self.capacity, self.bins.shape[1]))

    def add(
        self,
        bag: Path,
        index: int,
        t: float,
        log_s: float,
        row: tuple[float, ...],
        bins: np.ndarray | None = None,
    ) -> None:
        """One message: its stamp ``t`` and the bag's receive time ``log_s`` (s), its ``row``
        (:data:`ROW_FIELDS`' values in order; the sonar's bin size (m) after them) and a
        beam's ``bins``."""
        if self.n:
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
                self.first_fault.setdefault("out_of_order", index)
            elif t == self.last_t:
                self.repeated += 1
                self.first_fault.setdefault("repeated", index)
        if bins is not None:
            if self.bins is None:
                self.bins = np.empty((self.capacity, bins.size), dtype=np.uint8)
                self.bin_m = row[1]
            elif bins.size != self.bins.shape[1] or not math.isclose(
                row[1], self.bin_m, rel_tol=1e-4
            ):
                raise DataError(
                    bag,
                    None,
                    f"topic {self.topic} message {index}: a beam of {bins.size} bins of"
                    f" {row[1]:g} m after {self.bins.shape[1]} bins of {self.bin_m:g} m (the"
                    " head's range changed: one run a range)",
                )
        if self.n == self.capacity:
            self._grow()
        n = self.n
        self.t[n] = t
        k = 0
        for name, shape, _ in ROW_FIELDS[self.role]:
            if shape:
                self.fields[name][n] = row[k : k + shape[0]]
                k += shape[0]
            else:
                self.fields[name][n] = row[k]
                k += 1
        if bins is not None and self.bins is not None:
            self.bins[n] = bins
        self.n += 1
        self.last_t, self.last_log_s = t, log_s

    def arrays(self, bag: Path) -> tuple[np.ndarray, dict[str, np.ndarray], np.ndarray | None]:
        """``(t, fields, bins)``: views of the messages read, sorted by stamp (a warning counts
        the messages out of order; only they are moved, in place)."""
        n = self.n
        t = self.t[:n]
        fields = {name: x[:n] for name, x in self.fields.items()}
        bins = self.bins[:n] if self.bins is not None else None
        if self.repeated:
            warnings.warn(
                f"{bag}: topic {self.topic} ({self.role}): {self.repeated} message(s) with the"
                f" stamp of the one before (the first: message {self.first_fault['repeated']});"
                " the gates keep the first of a stamp",
                DataWarning,
                stacklevel=3,
            )
        if self.out_of_order and not self.sorted:
            self.sorted = True
            warnings.warn(
                f"{bag}: topic {self.topic} ({self.role}): {self.out_of_order} message(s) stamped"
                f" earlier than the one before (the first: message"
                f" {self.first_fault['out_of_order']}), sorted by stamp",
                DataWarning,
                stacklevel=3,
            )
            order = np.argsort(t, kind="stable")
            moved = np.flatnonzero(order != np.arange(n))
            source = order[moved]
            for x in (t, *fields.values(), *([bins] if bins is not None else [])):
                x[moved] = x[source]
        return t, fields, bins


#: The fields of each role's rows (name, shape of one row's value, dtype): sonar (angle rad;
#: the bin size, m, is checked against the first beam's, not kept), dvl (vx, vy m/s, bottom
#: lock, the message's own sigma m/s or NaN), imu (yaw rad, yaw rate rad/s), gps (lat, lon
#: deg, fix).
ROW_FIELDS: dict[str, tuple[tuple[str, tuple[int, ...], Any], ...]] = {
    "sonar": (("angle", (), np.float64),),
    "dvl": (("v", (2,), np.float64), ("valid", (), np.bool_), ("sigma", (), np.float64)),
    "imu": (("yaw", (), np.float64), ("rate", (), np.float64)),
    "gps": (("lat", (), np.float64), ("lon", (), np.float64), ("fix", (), np.bool_)),
}


def _field(msg: Any, *names: str) -> Any:
    """The first of ``names`` the message has (a definition's spellings differ between its
    ROS 1 original and its ROS 2 port: ``velocityInst``, ``velocityinst``)."""
    for name in names:
        if hasattr(msg, name):
            return getattr(msg, name)
    raise AttributeError(f"none of the fields {', '.join(names)}")


#: Sonar types whose beam angle turns counter-clockwise about their frame's z axis (REP-103):
#: a bag of these reads with ``[sonar] angle_sense = +1`` unless its ``sonarslam.toml`` says
#: otherwise. The Ping360's types give the head's own angle (clockwise seen from above).
REP103_SONAR_TYPES = ("sensor_msgs/msg/LaserScan", "marine_acoustic_msgs/msg/ProjectedSonarImage")


#: Beam angle fields read as radians, by sonar type: a value beyond 2 pi in magnitude (or not
#: finite) is refused, naming the unit slip (:func:`_checked_radians`).
_RADIAN_ANGLE_FIELDS = {
    "sensor_msgs/msg/LaserScan": "angle_min",
    "ping360_sonar/msg/SonarEcho": "angle",
    "ping360_sonar_msgs/msg/SonarEcho": "angle",
}


def _checked_radians(msgtype: str, angle: float) -> float:
    """``angle`` (rad) of a beam message, or a ValueError naming its field and the likely unit
    when it is not finite or beyond 2 pi in magnitude: the ROS 1 ``ping360_sonar`` node
    publishes ``SonarEcho.angle`` in gradians (0-399, its ``node.py``: ``msg.angle = angle``)
    although its ``.msg`` says rad; a ``LaserScan`` written in degrees shows the same way."""
    if math.isfinite(angle) and abs(angle) <= 2.0 * math.pi:
        return angle
    name = _RADIAN_ANGLE_FIELDS.get(msgtype, "angle")
    if not math.isfinite(angle):
        raise ValueError(f"{name} {angle!r} is not a beam angle (rad)")
    hint = (
        "gradians (0-399: the ROS 1 ping360_sonar node publishes the head's angle so, though"
        " its SonarEcho.msg says rad) or degrees?"
        if msgtype == "ping360_sonar/msg/SonarEcho"
        else "degrees (or gradians)?"
    )
    raise ValueError(
        f"{name} {angle:g} is beyond 2 pi rad: {hint} The field must be radians; convert the"
        " bag's angles (gradians * pi / 200, np.radians of degrees)"
    )


def _sonar_row(msgtype: str, msg: Any) -> tuple[float, float, np.ndarray]:
    """(transducer angle rad, bin size m, intensities uint8) of one beam message; a ValueError
    for an angle beyond 2 pi rad or not finite (:func:`_checked_radians`)."""
    if msgtype == "sensor_msgs/msg/LaserScan":
        values = np.asarray(msg.intensities, dtype=np.float64)
        bins = np.clip(np.rint(values), 0, 255).astype(np.uint8)
        angle = _checked_radians(msgtype, float(msg.angle_min))
        return angle, float(msg.range_max) / max(bins.size, 1), bins
    if msgtype == "ping360_sonar/msg/SonarEcho":
        bins = np.asarray(msg.intensities, dtype=np.uint8)
        angle = _checked_radians(msgtype, float(msg.angle))
        return angle, float(msg.range) / max(bins.size, 1), bins
    if msgtype == "ping360_sonar_msgs/msg/SonarEcho":
        bins = np.asarray(msg.intensities, dtype=np.uint8)
        angle = _checked_radians(msgtype, float(msg.angle))
        return angle, ping360_driver_bin_m(float(msg.range), bins.size, msg.speed_of_sound), bins
    if msgtype == "marine_acoustic_msgs/msg/ProjectedSonarImage":
        return _projected_row(msg)
    bins = np.asarray(msg.profile_data, dtype=np.uint8)
    grad = float(msg.angle)
    if not 0.0 <= grad < 400.0:
        raise ValueError(f"angle {grad:g} is not a Ping360 head angle (gradians, 0-399)")
    return grad * GRADIANS_TO_RAD, float(msg.range) / max(bins.size, 1), bins


#: The Ping360's sample period is whole ticks of 25 ns (ping-protocol ``sample_period``).
PING360_TICK_S = 25e-9


def ping360_driver_bin_m(range_m: float, n_samples: int, speed_of_sound_mps: float) -> float:
    """The bin size (m) of a beam the ROS 2 ``ping360_sonar`` driver asked for: it sets the
    head's ``sample_period`` to ``2 range / (n c 25 ns)`` truncated to whole ticks
    (``Ping360Interface::configureTransducer``, CentraleNantesRobotics/ping360_sonar at
    fa53b8f), so a sample spans ``c period 25 ns / 2``, up to one tick in ~80 (1.25 %) short
    of the ``range / n`` its ``rangeFrom`` and its message's ``range`` imply."""
    if n_samples < 1 or not speed_of_sound_mps > 0 or not range_m > 0:
        raise ValueError(
            f"range {range_m:g} m, {n_samples} samples at {speed_of_sound_mps:g} m/s: no bin size"
        )
    ticks = math.floor(2.0 * range_m / (n_samples * speed_of_sound_mps * PING360_TICK_S))
    return speed_of_sound_mps * max(ticks, 1) * PING360_TICK_S / 2.0


def _projected_row(msg: Any) -> tuple[float, float, np.ndarray]:
    """One beam of a ``ProjectedSonarImage``: its azimuth (rotation about the sonar's x axis,
    up, from its z axis, forward: ``atan2(-d_y, d_z)`` of the beam direction ``d``,
    counter-clockwise seen from above), 8-bit samples, bin size ``ranges[-1] / n``."""
    image = msg.image
    if int(image.beam_count) != 1 or len(msg.beam_directions) != 1:
        raise ValueError(
            f"{int(image.beam_count)} beams ({len(msg.beam_directions)} directions): one beam a"
            " message is read (a mechanically scanned head)"
        )
    if int(image.dtype) != 0:  # SonarImageData.DTYPE_UINT8
        raise ValueError(f"image dtype {int(image.dtype)}: only 8-bit samples (0) are read")
    bins = np.asarray(image.data, dtype=np.uint8)
    ranges = np.asarray(msg.ranges, dtype=np.float64)
    if ranges.size != bins.size or bins.size == 0:
        raise ValueError(f"{bins.size} samples for {ranges.size} ranges")
    d = msg.beam_directions[0]
    return math.atan2(-float(d.y), float(d.z)), float(ranges[-1]) / bins.size, bins


def _dvl_row(msgtype: str, msg: Any) -> tuple[float, float, float, float]:
    """(vx, vy m/s in the DVL frame, bottom lock 1/0, the message's own 1-sigma m/s or NaN)."""
    sigma = math.nan
    if msgtype in ("geometry_msgs/msg/TwistWithCovarianceStamped", "nav_msgs/msg/Odometry"):
        tw = msg.twist
        vx, vy = float(tw.twist.linear.x), float(tw.twist.linear.y)
        var = float(tw.covariance[0])
        ok = not var < 0.0
        sigma = math.sqrt(var) if var > 0.0 else math.nan
    elif msgtype in WATERLINKED_DVL_TYPES:
        vx, vy = float(msg.velocity.x), -float(msg.velocity.y)  # y right (the A50's) to left
        ok = bool(msg.velocity_valid)
        sigma = float(msg.fom)  # Water Linked: the velocities' figure of merit (m/s)
    elif msgtype in TRANSDUCER_REPORT_TYPES:
        r = msg.report
        vx, vy = float(r.vx), -float(r.vy)  # y right (the A50's) to left
        ok = bool(r.velocity_valid)
        sigma = float(r.fom)
    elif msgtype == "marine_acoustic_msgs/msg/Dvl":
        vx, vy = float(msg.velocity.x), float(msg.velocity.y)
        ok = int(msg.velocity_mode) == 1 and int(msg.num_good_beams) >= 3  # bottom track
        var = float(msg.velocity_covar[0])  # -1: not known
        sigma = math.sqrt(var) if var > 0.0 else math.nan
    else:  # cirs_girona_cala_viuda/msg/LinkquestDvl: the instrument-frame velocity
        v = _field(msg, "velocityInst", "velocityinst", "velocity_inst")
        vx, vy = float(v[0]), float(v[1])
        ok = int(_field(msg, "velocityInstFlag", "velocityinstflag", "velocity_inst_flag")) == 1
    ok = ok and math.isfinite(vx) and math.isfinite(vy)
    return (vx if ok else 0.0), (vy if ok else 0.0), float(ok), sigma if ok else math.nan


#: How far an IMU's orientation may be from a unit quaternion before it is not an orientation.
QUATERNION_NORM_TOL = 0.05


def _imu_row(msg: Any) -> tuple[float, float]:
    """(yaw of ``orientation`` rad ENU, ``angular_velocity.z`` rad/s). Raises ValueError for a
    message that gives no orientation (REP-145: ``orientation_covariance[0] = -1``, as raw IMU
    topics publish) or one that is not a unit quaternion."""
    if float(msg.orientation_covariance[0]) == -1.0:
        raise ValueError(
            "orientation_covariance[0] = -1: the IMU gives no orientation (REP-145; a raw IMU"
            " topic such as /mavros/imu/data_raw): sonarslam needs the heading, name a topic"
            " with the fused orientation ([topics] imu)"
        )
    q = msg.orientation
    x, y, z, w = float(q.x), float(q.y), float(q.z), float(q.w)
    norm = math.sqrt(x * x + y * y + z * z + w * w)
    if not abs(norm - 1.0) <= QUATERNION_NORM_TOL:
        raise ValueError(f"orientation ({x:g}, {y:g}, {z:g}, {w:g}) is not a unit quaternion")
    yaw = math.atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))
    return yaw, float(msg.angular_velocity.z)


def _gps_row(msg: Any) -> tuple[float, float, float]:
    lat, lon = float(msg.latitude), float(msg.longitude)
    fix = int(msg.status.status) >= 0 and math.isfinite(lat) and math.isfinite(lon)
    return lat, lon, float(fix and not (lat == 0.0 and lon == 0.0))


TF_TOPICS = ("/tf_static", "/tf")


def _read_columns(
    bag: Path, r: _Reader, roles: dict[str, str]
) -> tuple[dict[str, _Column], dict[tuple[str, str], Any]]:
    """One pass over the bag's messages of the roles' topics (and its transforms: every
    ``/tf_static`` message; ``/tf`` only without ``/tf_static``, until each role's frame is
    linked); the columns and the transforms ``(parent, child) -> Transform``."""
    by_topic = {topic: role for role, topic in roles.items()}
    reader = r.reader
    info = reader.topics
    columns = {
        role: _Column(bag, role, topic, info[topic].msgcount) for role, topic in roles.items()
    }
    tf_topic = next((t for t in TF_TOPICS if t in info), None)
    conns = [c for c in reader.connections if c.topic in by_topic or c.topic == tf_topic]
    counts = dict.fromkeys([*by_topic, tf_topic], 0)
    edges: dict[tuple[str, str], Any] = {}
    tf_done = tf_topic is None
    topic = ""
    try:
        for conn, log_ns, raw in reader.messages(connections=conns):
            topic = conn.topic
            index = counts[topic]
            counts[topic] += 1
            if topic == tf_topic:
                if not tf_done:
                    msg = _decode(bag, reader, raw, conn.msgtype, topic, index)
                    for tf in msg.transforms:
                        key = (tf.header.frame_id.lstrip("/"), tf.child_frame_id.lstrip("/"))
                        edges.setdefault(key, tf.transform)
                    tf_done = topic == "/tf" and index % 50 == 49 and _linked(columns, edges)
                continue
            role = by_topic[topic]
            msg = _decode(bag, reader, raw, conn.msgtype, topic, index)
            try:
                if role == "sonar":
                    angle, size_m, bins = _sonar_row(conn.msgtype, msg)
                    row: tuple[float, ...] = (angle, size_m)
                elif role == "dvl":
                    row, bins = _dvl_row(conn.msgtype, msg), None
                elif role == "imu":
                    row, bins = _imu_row(msg), None
                else:
                    row, bins = _gps_row(msg), None
            except (AttributeError, ValueError, TypeError, IndexError) as exc:
                raise DataError(
                    bag,
                    None,
                    f"topic {topic} ({conn.msgtype}) message {index}: {_one_line(exc)}",
                ) from None
            t = _stamp(msg)
            if not math.isfinite(t) or t <= 0.0:
                raise DataError(
                    bag, None, f"topic {topic} message {index}: stamp {t!r} is not a time"
                )
            column = columns[role]
            if not column.n and hasattr(msg, "header"):
                column.frame = str(msg.header.frame_id).lstrip("/")
            column.add(bag, index, t, log_ns * 1e-9, row, bins)
    except DataError:
        raise
    except Exception as exc:  # a bag cut short, a bad chunk: where the reading stopped
        where = f" after message {counts.get(topic, 0) - 1} of {topic}" if topic else ""
        raise DataError(bag, None, f"the bag cannot be read on{where}: {_one_line(exc)}") from None
    return columns, edges


def _decode(bag: Path, reader: Any, raw: bytes, msgtype: str, topic: str, index: int) -> Any:
    try:
        return reader.deserialize(raw, msgtype)
    except Exception as exc:
        if msgtype in OLDER_DEFINITIONS:
            try:
                return reader.deserialize(raw, OLDER_DEFINITIONS[msgtype][0])
            except Exception:  # neither layout: the first error is the one to say
                pass
        raise DataError(
            bag,
            None,
            f"topic {topic} ({msgtype}) message {index}: cannot be decoded: {_one_line(exc)}",
        ) from None


def _linked(columns: dict[str, _Column], edges: dict[tuple[str, str], Any]) -> bool:
    """Every role with a message has its frame in the transforms read so far."""
    children = {c for _, c in edges}
    return all(c.frame in children for c in columns.values() if c.n and c.frame)


@dataclass(frozen=True)
class BagRoles:
    """What :func:`read_roles` read of a bag: a series per role read (None for a role not
    asked, without a topic or without a message), as the bag has them (not yet gated).

    Attributes
    ----------
    bag : Path
    topics : dict of str to str
        Role -> the topic read for it.
    beams : BeamSeries or None
        The sonar: stamps (Unix s), transducer angles as the messages give them (rad),
        ``(N, n_bins)`` uint8 intensities.
    bin_size_m : float
        The beams' bin size (m; NaN without beams).
    dvl : DvlSeries or None
        Velocities in the DVL's frame (m/s) with bottom lock; ``heading_rad`` NaN.
    attitude : AttitudeSeries or None
        Yaw (rad, ENU) and yaw rate (rad/s) of the IMU's frame.
    gps : GpsSeries or None
        East-North (m) from the first fix: a ruler only.
    counts : dict of str to int
        ``<role>_out_of_order`` and ``<role>_repeated``: the messages stamped earlier than the
        one before (sorted into the series) and with its stamp (kept; the gates drop them).
    frames : dict of str to str
        Role -> ``header.frame_id`` of its first message (without a leading ``/``).
    transforms : dict
        ``(parent, child)`` frame -> ``geometry_msgs/Transform`` of the bag's ``/tf_static``
        (else the first ``/tf`` messages, until each role's frame is linked).
    base_frame : str or None
        ``[topics] base_frame`` (or its preset's), when given.
    dvl_sigma_mps : tuple of (float, int)
        The median and the count of the DVL messages' own finite 1-sigma (a covariance, or
        Water Linked's figure of merit; m/s); ``(nan, 0)`` without.
    msgtypes : dict of str to str
        Role -> the message type of its topic (``sensor_msgs/msg/LaserScan``).
    """

    bag: Path
    topics: dict[str, str]
    beams: BeamSeries | None
    bin_size_m: float
    dvl: DvlSeries | None
    attitude: AttitudeSeries | None
    gps: GpsSeries | None
    counts: dict[str, int]
    frames: dict[str, str]
    transforms: dict[tuple[str, str], Any]
    base_frame: str | None
    dvl_sigma_mps: tuple[float, int]
    msgtypes: dict[str, str]


def read_roles(
    bag: str | Path,
    roles: tuple[str, ...] = ROLES,
    required: tuple[str, ...] = REQUIRED_ROLES,
    topics_file: str | Path | None = None,
    purpose: str = "",
) -> BagRoles:
    """Read these ``roles`` of a bag (a subset of :data:`ROLES`) in one streamed pass.

    The topic of each role is found as the module docstring says (``[topics]`` of
    ``topics_file``, a preset's name, or the bag's ``sonarslam.toml``; else the one topic of a
    type that fits); the topics of the roles not asked are not read. Each message's row goes
    into arrays preallocated from the bag's count of its topic, and the series are views of
    them: the memory beyond the series does not grow with the bag's length.

    Parameters
    ----------
    bag : str or Path
        A ROS 1 ``.bag``, a ``.mcap`` file or a ROS 2 bag directory.
    roles : tuple of str
        The roles to read.
    required : tuple of str
        The roles that must have a topic and a message (a :class:`DataError` otherwise, whose
        text ``purpose`` completes: " of the Ping360's navigation").
    topics_file : str or Path, optional
        A TOML file with ``[topics]``, or the name of a :data:`TOPIC_PRESETS` preset.

    Raises
    ------
    DataError
        Naming the bag (or the ``[topics]`` file), the topic and the message's index: a
        required role without a topic or a message, a topic of a type that cannot play its
        role, a message that cannot be decoded, a clock jump, a bag cut short, a beam of
        another bin count, a GPS without any fix.
    """
    p = Path(bag)
    if not is_bag(p):
        raise DataError(p, None, "not a ROS bag (.bag, .mcap, or a directory with metadata.yaml)")
    unknown = sorted(set(roles) - set(ROLES))
    if unknown or not set(required) <= set(roles):
        raise ValueError(f"roles must be among {ROLES} and hold required, got {roles}, {required}")
    table, table_path = _topics_table(p, topics_file)
    with _Reader(p) as r:
        types = {t: i.msgtype or "" for t, i in r.reader.topics.items()}
        table = _with_preset(types, table)
        found = _roles(p, types, table, table_path, roles)
        missing = [role for role in required if role not in found]
        if missing:
            listing = ", ".join(f"{t} ({ty})" for t, ty in sorted(types.items())) or "none"
            raise DataError(
                p,
                None,
                f"no topic for the {', '.join(missing)}{purpose} (types: "
                + "; ".join(f"{m}: {', '.join(ROLE_TYPES[m])}" for m in missing)
                + f"); the bag's topics: {listing}",
            )
        columns, edges = _read_columns(p, r, found)
    for role in required:
        if not columns[role].n:
            raise DataError(p, None, f"topic {found[role]} ({role}) has no message")
    has = {role: c for role, c in columns.items() if c.n}
    sigma = _dvl_sigma(has["dvl"]) if "dvl" in has else (math.nan, 0)
    beams = _beams(p, has["sonar"]) if "sonar" in has else None
    return BagRoles(
        bag=p,
        topics=found,
        beams=beams[0] if beams is not None else None,
        bin_size_m=beams[2] if beams is not None else math.nan,
        dvl=_dvl(p, has["dvl"]) if "dvl" in has else None,
        attitude=_imu(p, has["imu"]) if "imu" in has else None,
        gps=_gps(p, has["gps"]) if "gps" in has else None,
        counts={
            **{f"{role}_out_of_order": c.out_of_order for role, c in columns.items()},
            **{f"{role}_repeated": c.repeated for role, c in columns.items()},
        },
        frames={role: c.frame for role, c in has.items() if c.frame},
        transforms=edges,
        base_frame=table.get("base_frame"),
        dvl_sigma_mps=sigma,
        msgtypes={role: types[topic] for role, topic in found.items()},
    )


def open_bag(
    bag: str | Path,
    config_override: str | Path | None = None,
    topics_file: str | Path | None = None,
) -> Dataset:
    """Read a bag into a gated :class:`Dataset` (module docstring).

    The configuration, lowest first: neutral (:data:`NEUTRAL_CALIBRATION`); the mountings of the
    sonar, DVL and IMU from the bag's transforms (``/tf_static``, else the constant sensor
    offsets on ``/tf``: each message's ``header.frame_id`` below the base frame, ``base_link``
    or ``[topics] base_frame`` or the sensors' nearest common parent); the bag's
    ``sonarslam.toml`` (inside a bag directory or beside a bag file), whose ``[mounting.X]``
    table replaces the transforms' mounting of X whole; ``config_override``'s keys. Without
    a ``sonarslam.toml`` nor transforms a :class:`DataWarning` says the run is neutral.
    :attr:`Dataset.calibration` says which came from where. The head's ``n_bins`` and
    ``bin_size_m`` are the messages' own (a ``sonarslam.toml`` that says otherwise is a
    :class:`DataError`).
    """
    p = Path(bag)
    read = read_roles(p, ROLES, REQUIRED_ROLES, topics_file)
    assert read.beams is not None and read.dvl is not None and read.attitude is not None
    mountings, tf_line = tf_mountings(p, read.frames, read.transforms, read.base_frame)
    toml = _beside(p, "sonarslam.toml")
    base = DatasetConfig()
    if read.msgtypes.get("sonar") in REP103_SONAR_TYPES:
        base = replace(base, sonar=replace(base.sonar, angle_sense=1))
    in_toml = mounting_tables(toml)
    config = _with_mountings(base, mountings, in_toml)
    if toml is not None:
        config, calibration = load_dataset_config(toml, base=config), str(toml)
        if tf_line:
            calibration += f"; {tf_line}, where it has no [mounting.*] table"
    elif tf_line:
        calibration = f"neutral but {tf_line}: no sonarslam.toml"
    else:
        calibration = NEUTRAL_CALIBRATION
        if config_override is None:
            warnings.warn(neutral_warning(p), DataWarning, stacklevel=2)
    if config_override is not None:
        config = load_dataset_config(config_override, base=config)
        calibration = f"{calibration}; over it {config_override}"
    if calibration != NEUTRAL_CALIBRATION:  # a neutral run is said whole above
        warn_assumed_mountings(p, config, in_toml | mounting_tables(config_override))
    dvl_note = _dvl_sigma_note(p, read.topics["dvl"], read.dvl_sigma_mps, config)
    if dvl_note:
        calibration = f"{calibration}; {dvl_note}"
    n_bins, bin_m = int(read.beams.intensities.shape[1]), read.bin_size_m
    sonar_head = replace(config.sonar, n_bins=n_bins, bin_size_m=bin_m)
    # the file that set the head last: --config's over the bag's own
    files = (Path(config_override) if config_override is not None else None, toml)
    head_file = next((f for f in files if f is not None and _file_sets_head(f)), None)
    if head_file is not None and (
        config.sonar.n_bins != n_bins or not math.isclose(config.sonar.bin_size_m, bin_m)
    ):
        raise DataError(
            head_file,
            toml_file_line(
                head_file,
                "sonar",
                ("n_bins", "bin_size_m")
                if config.sonar.n_bins != n_bins
                else ("bin_size_m", "n_bins"),
            ),
            f"[sonar] n_bins {config.sonar.n_bins}, bin_size_m {config.sonar.bin_size_m:g}: the"
            f" bag's beams have {n_bins} bins of {bin_m:g} m (leave them out; the bag's win)",
        )
    config = replace(config, sonar=_beams_step(sonar_head, read.beams, files))
    series = read.beams
    if config.sonar_time_offset_s:
        series = series.shifted(config.sonar_time_offset_s)
    truth = _beside(p, "truth.json")
    name = p.stem if p.is_file() else p.name
    d = gated_dataset(
        name,
        p,
        config,
        series,
        read.dvl,
        read.attitude,
        read.gps,
        calibration,
        truth=read_truth(truth) if truth is not None else None,
    )
    d.report.counts.update(read.counts)
    if topics_file is not None and str(topics_file) not in TOPIC_PRESETS:
        d = replace(d, inputs=(Path(topics_file),))
    return d


def _beams_step(head: SonarHead, beams: BeamSeries, files: tuple[Path | None, ...]) -> SonarHead:
    """The head with the step between beams the beams show (:meth:`BeamSeries.step_rad`, made
    a whole division of the turn): the sector store, the Hough resolution and the scans count
    beams by it, so a wrong step silently halves or doubles the sector. A ``[sonar] step_deg``
    in ``files`` (the override's, then the bag's own ``sonarslam.toml``) more than
    :data:`STEP_TOLERANCE` off it is a :class:`DataError` naming its line; within it the file's
    value is kept. Beams that show no step keep the head's."""
    seen = beams.step_rad()
    if seen is None:
        return head
    per_turn = max(int(round(2.0 * math.pi / seen)), 1)
    step = 2.0 * math.pi / per_turn
    for f in files:
        line = toml_file_line(f, "sonar", ("step_deg",)) if f is not None else None
        if f is None or line is None:
            continue
        if abs(head.step_rad / step - 1.0) > STEP_TOLERANCE:
            raise DataError(
                f,
                line,
                f"[sonar] step_deg {math.degrees(head.step_rad):g}: the bag's beams step by"
                f" {math.degrees(seen):.3g} deg ({per_turn} a turn; leave step_deg out, the"
                " beams' own is taken)",
            )
        return head
    return replace(head, step_rad=step)


def _file_sets_head(toml: Path) -> bool:
    try:
        sonar = tomllib.loads(toml.read_text(encoding="utf-8")).get("sonar", {})
    except (OSError, tomllib.TOMLDecodeError):
        return False
    return isinstance(sonar, dict) and ("n_bins" in sonar or "bin_size_m" in sonar)


def _beams(bag: Path, col: _Column) -> tuple[BeamSeries, int, float]:
    t, fields, bins = col.arrays(bag)
    assert bins is not None
    n_bins, bin_m = int(bins.shape[1]), float(col.bin_m)
    if n_bins == 0 or not bin_m > 0.0:
        raise DataError(
            bag, None, f"topic {col.topic} message 0: a beam of {n_bins} bins over {bin_m:g} m"
        )
    return BeamSeries(t, fields["angle"], bins, False), n_bins, bin_m


def _dvl(bag: Path, col: _Column) -> DvlSeries:
    t, fields, _ = col.arrays(bag)
    return DvlSeries(t, fields["v"], fields["valid"], np.full(t.size, np.nan), bag)


def _dvl_sigma(col: _Column) -> tuple[float, int]:
    """The median and the count of the DVL messages' own finite 1-sigma (m/s)."""
    sigma = col.fields["sigma"][: col.n]
    sigma = sigma[np.isfinite(sigma)]
    return (float(np.median(sigma)), int(sigma.size)) if sigma.size else (math.nan, 0)


def _dvl_sigma_note(bag: Path, topic: str, sigma: tuple[float, int], config: DatasetConfig) -> str:
    """The DVL messages' own 1-sigma (median, count: a covariance, or Water Linked's figure of
    merit) beside the ``[noise] dvl_sigma_mps`` the estimators take; a warning when the
    median exceeds it."""
    median, count = sigma
    if not count:
        return ""
    note = (
        f"DVL: the messages' own sigma (median {median:.3g} m/s over {count}) is not an"
        f" input; the estimators take [noise] dvl_sigma_mps = {config.noise.dvl_sigma_mps:g}"
    )
    if median > config.noise.dvl_sigma_mps:
        warnings.warn(
            f"{bag}: topic {topic}: {note} (set it in sonarslam.toml)",
            DataWarning,
            stacklevel=3,
        )
    return note


def _imu(bag: Path, col: _Column) -> AttitudeSeries:
    t, fields, _ = col.arrays(bag)
    yaw, rate = fields["yaw"], fields["rate"]
    check_heading_sense(
        bag,
        f"topic {col.topic} (imu): the orientation's heading turns against angular_velocity.z",
        t,
        yaw,
        rate,
    )
    return AttitudeSeries(t, yaw, rate, bag)


def _gps(bag: Path, col: _Column) -> GpsSeries:
    t, fields, _ = col.arrays(bag)
    fix = fields["fix"]
    if not fix.any():
        raise DataError(bag, None, f"topic {col.topic} (gps): no message with a fix")
    first = int(np.flatnonzero(fix)[0])
    lat0, lon0 = float(fields["lat"][first]), float(fields["lon"][first])
    lat = np.where(fix, fields["lat"], lat0)
    lon = np.where(fix, fields["lon"], lon0)
    en = geodetic_to_local_en(lat, lon, lat0, lon0)
    return GpsSeries(t, en, (lat0, lon0), fix, bag)


# -- sensor mountings from the bag's transforms -------------------------------------------------

#: The roles whose frames are mountings (the GPS is a ruler) and their DatasetConfig field.
MOUNTED_ROLES = {"sonar": "sonar_mounting", "dvl": "dvl_mounting", "imu": "ahrs_mounting"}
#: A sonar whose frame's z axis leans further than this from the base's (deg) is not a
#: horizontal head: an error rather than a map drawn in the wrong plane.
MAX_SONAR_TILT_DEG = 25.0


def _quat_matrix(q: Any) -> np.ndarray:
    x, y, z, w = float(q.x), float(q.y), float(q.z), float(q.w)
    n = math.sqrt(x * x + y * y + z * z + w * w)
    if not n > 0.0 or not math.isfinite(n):
        raise ValueError(f"rotation ({x}, {y}, {z}, {w}) is not a quaternion")
    x, y, z, w = x / n, y / n, z / n, w / n
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )


def _chain(
    edges: dict[tuple[str, str], Any], base: str, frame: str
) -> tuple[np.ndarray, np.ndarray] | None:
    """``(R, p)`` of ``frame`` in ``base`` (``base`` -> ... -> ``frame`` by the transforms'
    parent links), or None when ``frame`` does not hang below ``base``."""
    parent = {c: (p, tf) for (p, c), tf in edges.items()}
    R, p = np.eye(3), np.zeros(3)
    node, seen = frame, set()
    while node != base:
        if node not in parent or node in seen:
            return None
        seen.add(node)
        up, tf = parent[node]
        Ru = _quat_matrix(tf.rotation)
        pu = np.array([float(tf.translation.x), float(tf.translation.y), float(tf.translation.z)])
        R, p = Ru @ R, Ru @ p + pu
        node = up
    return R, p


def _ancestors(edges: dict[tuple[str, str], Any], frame: str) -> list[str]:
    parent = {c: p for p, c in edges}
    out = [frame]
    while out[-1] in parent and parent[out[-1]] not in out:
        out.append(parent[out[-1]])
    return out


def _base_frame(edges: dict[tuple[str, str], Any], frames: list[str], given: str | None) -> str:
    """The base frame: the one given, else ``base_link`` when the transforms have it, else the
    nearest frame that is an ancestor of (or is) every sensor frame."""
    if given:
        return given
    if any("base_link" in pair for pair in edges):
        return "base_link"
    chains = [_ancestors(edges, f) for f in frames]
    common = set(chains[0]).intersection(*chains[1:]) if chains else set()
    return next((f for f in chains[0] if f in common), "") if chains else ""


def tf_mountings(
    bag: Path,
    role_frames: dict[str, str],
    edges: dict[tuple[str, str], Any],
    base_frame: str | None,
) -> tuple[dict[str, Mounting], str]:
    """The mountings (``bTs``: x, y, yaw of the sensor frame's x axis in the base's plane) of
    the roles whose ``header.frame_id`` (``role_frames``) hangs below the base frame in the
    bag's transforms; and a line saying which (empty when none)."""
    frames = {role: f for role, f in role_frames.items() if role in MOUNTED_ROLES and f}
    if not edges or not frames:
        return {}, ""
    base = _base_frame(edges, sorted(set(frames.values())), base_frame)
    out: dict[str, Mounting] = {}
    said = []
    for role, frame in frames.items():
        try:
            found = _chain(edges, base, frame) if base else None
        except ValueError as exc:
            raise DataError(bag, None, f"transform of frame {frame}: {exc}") from None
        if found is None:
            continue
        R, p = found
        if role == "sonar" and abs(R[2, 2]) < math.cos(math.radians(MAX_SONAR_TILT_DEG)):
            raise DataError(
                bag,
                None,
                f"the sonar's frame {frame} leans {math.degrees(math.acos(min(1.0, abs(R[2, 2])))):.0f}"
                f" deg from {base}'s z axis: not a horizontal head",
            )
        yaw = math.atan2(R[1, 0], R[0, 0])
        flipped = role == "sonar" and R[2, 2] < 0.0
        if flipped:
            warnings.warn(
                f"{bag}: the sonar's frame {frame} is upside down in {base}: its angles turn"
                " the other way ([sonar] angle_sense in sonarslam.toml)",
                DataWarning,
                stacklevel=3,
            )
        source = f"transforms of {bag.name}: {base} -> {frame}"
        try:
            out[role] = Mounting(x_m=float(p[0]), y_m=float(p[1]), yaw_rad=yaw, source=source)
        except ValueError as exc:
            raise DataError(bag, None, f"transform {base} -> {frame} ({role}): {exc}") from None
        said.append(f"{role} ({frame})")
    line = f"mountings of {', '.join(said)} from the bag's transforms (base {base})" if said else ""
    return out, line


def _with_mountings(
    config: DatasetConfig, mountings: dict[str, Mounting], tables: set[str]
) -> DatasetConfig:
    """``config`` with the transforms' mountings, except those whose ``[mounting.<sensor>]``
    table the ``sonarslam.toml`` has (``tables``, :func:`sonarslam.datasets.dataset.mounting_tables`: the file wins,
    table by table)."""
    changes: dict[str, Any] = {
        MOUNTED_ROLES[role]: m
        for role, m in mountings.items()
        if MOUNTED_ROLES[role].removesuffix("_mounting") not in tables
    }
    return replace(config, **changes)


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


def transform_msg(
    store: Any,
    t: float,
    parent: str,
    child: str,
    x_m: float,
    y_m: float,
    yaw_rad: float,
    z_m: float = 0.0,
) -> Any:
    """A ``geometry_msgs/TransformStamped`` at ``t`` (Unix s): ``child`` in ``parent``'s frame,
    at (``x_m``, ``y_m``, ``z_m``) and turned by ``yaw_rad`` about z."""
    T = store.types
    return T["geometry_msgs/msg/TransformStamped"](
        header=_header(store, t, parent),
        child_frame_id=child,
        transform=T["geometry_msgs/msg/Transform"](
            translation=T["geometry_msgs/msg/Vector3"](x=x_m, y=y_m, z=z_m),
            rotation=T["geometry_msgs/msg/Quaternion"](
                x=0.0, y=0.0, z=math.sin(yaw_rad / 2), w=math.cos(yaw_rad / 2)
            ),
        ),
    )


def _messages(store: Any, d: Dataset) -> Iterator[tuple[float, str, Any]]:
    """(time, role, message) of a dataset in time order: the inverse of :func:`open_bag`."""
    T = store.types
    vec = T["geometry_msgs/msg/Vector3"]
    if d.beams.bin_size_m is not None and np.any(d.beams.bin_size_m != d.config.sonar.bin_size_m):
        # the bag's reader takes one range for every beam: written with the head's, a
        # segment's echoes would read back at the wrong ranges
        raise ValueError(
            f"{d.root}: beams of several bin sizes (segments) cannot be written as a bag of one"
            " range: take one segment (--span, datasets.dataset.dataset_span)"
        )
    n = d.config.sonar.n_bins
    range_m = n * d.config.sonar.bin_size_m
    ranges = (np.arange(1, n + 1) * d.config.sonar.bin_size_m).astype(np.float32)
    cov36 = np.zeros(36)
    cov9 = np.zeros(9)
    beams = d.beams.shifted(-d.config.sonar_time_offset_s)
    sense = d.config.sonar.angle_sense

    def head(t: float, frame: str) -> Any:
        return _header(store, t, frame)

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
            # REP-103: the bearing in the sonar frame, counter-clockwise (bag_config)
            angle = float(np.mod(sense * beams.transducer_angle_rad[i], 2.0 * math.pi))
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


#: The caves data set's frames of its sensors, below ``sparus`` (the preset's base frame).
CAVES_FRAMES = {"sonar": "sonar_micron", "dvl": "dvl_linkquest", "imu": "imu_adis"}


def _caves_messages(store: Any, d: Dataset) -> Iterator[tuple[float, str, Any]]:
    """:func:`_messages` in the caves data set's shape (:data:`TOPIC_PRESETS` ``caves``): the
    DVL as ``LinkquestDvl`` (``velocityinst``, flag 1 with bottom lock), each message's frame
    the sensor's, and at every AHRS message a ``/tf`` with the vehicle (``world -> sparus``, at
    the origin: the data set's own is its dead reckoning) and the sensor offsets (the
    dataset's mountings); no GPS."""
    T = store.types
    z3, z4 = np.zeros(3), np.zeros(4)
    mounts = {
        CAVES_FRAMES["sonar"]: d.config.sonar_mounting,
        CAVES_FRAMES["dvl"]: d.config.dvl_mounting,
        CAVES_FRAMES["imu"]: d.config.ahrs_mounting,
    }

    for t, role, msg in _messages(store, replace(d, gps=None)):
        msg.header.frame_id = CAVES_FRAMES[role]
        if role == "dvl":
            v = msg.twist.twist.linear
            ok = int(msg.twist.covariance[0] >= 0.0)
            msg = T["cirs_girona_cala_viuda/msg/LinkquestDvl"](
                header=msg.header, errcode="", datagood=np.full(4, ok, np.int32),
                altitudebeam=z4, bottomvelocitybeam=z4, watervelocitybeam=z4,
                watervelocitycredit=z4, velocityinst=np.array([v.x, v.y, 0.0]),
                velocityinstflag=ok, velocityearth=z3, velocityearthflag=0,
                watervelocityinst=z3, watervelocityinstflag=0, watervelocityearth=z3,
                watervelocityearthflag=0, roll=0.0, pitch=0.0, heading=0.0, altitude=0.0,
                temperature=0.0, pressure=0.0, salinity=0.0, soundspeed=1500.0, rawdata="",
            )  # fmt: skip
        yield t, role, msg
        if role == "imu":
            tfs = [transform_msg(store, t, "world", "sparus", 0.0, 0.0, 0.0)]
            tfs += [
                transform_msg(store, t, "sparus", f, m.x_m, m.y_m, m.yaw_rad)
                for f, m in mounts.items()
            ]
            yield t, "tf", T["tf2_msgs/msg/TFMessage"](transforms=tfs)


def bag_config(config: DatasetConfig) -> DatasetConfig:
    """The configuration of a bag :func:`write_bag` writes of a dataset of ``config``: its
    ``LaserScan`` angles are bearings in the sonar frame, counter-clockwise (REP-103), so
    ``[sonar] angle_sense = +1``; the rest is ``config``'s."""
    return replace(config, sonar=replace(config.sonar, angle_sense=1))


def write_bag(d: Dataset, path: str | Path, kind: str, preset: str | None = None) -> Path:
    """Write a dataset's beams (``LaserScan``, each angle the bearing in the sonar frame,
    counter-clockwise: REP-103; :func:`bag_config`), DVL (``TwistWithCovarianceStamped``), AHRS
    (``Imu``) and GPS (``NavSatFix``) as a bag: ``kind`` ``"ros1"`` (``path`` a ``.bag`` file),
    ``"mcap"`` or ``"sqlite3"`` (``path`` a ROS 2 bag directory). Each message's receive time
    is its stamp. ``preset="caves"``: in the caves data set's shape instead
    (:func:`_caves_messages`: its topics, its DVL message, its frames on ``/tf``). Returns
    ``path``."""
    from rosbags.rosbag1 import Writer as Writer1  # lazy: only bags load rosbags
    from rosbags.rosbag2 import StoragePlugin  # lazy: only bags load rosbags
    from rosbags.rosbag2 import Writer as Writer2  # lazy: only bags load rosbags

    if kind not in BAG_KINDS:
        raise ValueError(f"bag kind must be one of {BAG_KINDS}, got {kind!r}")
    if preset not in (None, "caves"):
        raise ValueError(f"bag preset must be None or 'caves', got {preset!r}")
    p = Path(path)
    store = _typestore(ros1=kind == "ros1")
    types = {
        "sonar": "sensor_msgs/msg/LaserScan",
        "dvl": "geometry_msgs/msg/TwistWithCovarianceStamped",
        "imu": "sensor_msgs/msg/Imu",
        "gps": "sensor_msgs/msg/NavSatFix",
    }
    topics = dict(WRITTEN_TOPICS)
    roles = [r for r in ROLES if r != "gps" or d.gps is not None]
    messages = _messages(store, d)
    if preset == "caves":
        caves = TOPIC_PRESETS["caves"]
        topics = {r: caves[r] for r in ("sonar", "dvl", "imu")} | {"tf": "/tf"}
        types |= {"dvl": "cirs_girona_cala_viuda/msg/LinkquestDvl", "tf": "tf2_msgs/msg/TFMessage"}
        roles = list(topics)
        messages = _caves_messages(store, d)
    if kind == "ros1":
        with Writer1(p) as w1:
            conns = {r: w1.add_connection(topics[r], types[r], typestore=store) for r in roles}
            for t, role, msg in messages:
                raw = store.serialize_ros1(msg, types[role])
                w1.write(conns[role], int(round(t * 1e9)), raw)
        return p
    plugin = StoragePlugin.MCAP if kind == "mcap" else StoragePlugin.SQLITE3
    with Writer2(p, version=9, storage_plugin=plugin) as w2:
        conns = {r: w2.add_connection(topics[r], types[r], typestore=store) for r in roles}
        for t, role, msg in messages:
            raw = store.serialize_cdr(msg, types[role])
            w2.write(conns[role], int(round(t * 1e9)), raw)
    return p
