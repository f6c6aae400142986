"""Ping Viewer ``.bin`` logs of a Blue Robotics Ping360, with the navigation from a ROS bag or a
CSV: read (streamed) into a :class:`sonarslam.datasets.dataset.Dataset`, and written (the
simulator's round trip).

The ``.bin`` layout (Ping Viewer's ``FileLink``/``LogSensorStruct``, written through Qt's
``QDataStream``, big-endian; ``src/link/filelink.cpp`` and ``src/link/logsensorstruct.cpp`` of
github.com/bluerobotics/ping-viewer, and its ``examples/decode_sensor_binary_log.py``; what a
record holds from ``src/sensor/sensor.cpp`` and ``src/link/seriallink.cpp``, the ranges from
``src/sensor/ping360.h``/``.cpp``; the framing from ``brping/pingmessage.py``'s ``PingParser``
of github.com/bluerobotics/ping-python; read at ping-viewer commit 1ed4508, ping-python
13338a0 and ``bluerobotics-ping`` 0.2.5):

* a header: the string ``"PingViewer sensor log file"``, the log version (int32, 1), five
  strings of Ping Viewer's build (hash, date, tag, OS name, OS version), the sensor family and
  type (two int32);
* then records, each a time stamp string ``"hh:mm:ss.zzz"`` and the bytes Ping Viewer's link
  read at once (``FileLink::writeData`` logs what ``Sensor::connectLinkLog`` passes on from the
  link's ``newData``: ``SerialLink`` emits ``readAll()`` on each ``readyRead``). A record is
  not a message: one message's bytes may straddle two records, and a record may hold several.
  The records' bytes are read as one stream and framed into messages across them
  (:class:`_Framer`); a message takes the stamp of the record that holds its first byte.

A string is a uint32 byte count (``0xFFFFFFFF``: a null string) and its bytes: UTF-16
big-endian as ``QDataStream`` writes a ``QString``; logs in UTF-8 exist too (the reference
decoder takes UTF-8 unless the header string holds NUL bytes), so both are read, told apart by
the header. A message's bytes are a uint32 count and the bytes.

The time stamp is *not* a time of day: since July 2019 (ping-viewer commit f893d00) it is the
time elapsed since the log was opened (``QElapsedTimer``) formatted as a time of day; the date
and time of the start are only in the file name, ``yyyyMMdd-hhmmsszzz.bin``
(``src/filemanager/filemanager.h``), in the logging computer's local time. Qt 5 formats both
in the system locale's digits: a Persian-locale Windows writes them in Extended Arabic-Indic
digits (U+06F0-U+06F9); any script's decimal digits are read (:func:`ascii_digits`). Older logs stamped
the computer's time of day. :attr:`Ping360Settings.stamps` ``"auto"`` takes the stamps as a
time of day when the first one is nearer the file name's time of day than zero, else as elapsed
time. A stamp more than 12 h earlier than the one before has crossed midnight (a day is added,
counted ``ping360_midnight_wraps``); Qt writes an empty stamp after 24 h of logging, where Ping
Viewer's own reader stops, and so does this one (a warning counts the bytes left).

A message (ping-protocol, little-endian, as ``bluerobotics-ping``'s ``brping.PingMessage``
packs it): ``"BR"``, payload length (uint16), message id (uint16), source and destination
device ids (uint8 each), the payload, and a checksum (uint16, the sum of all bytes before it).
The beams are ``device_data`` (2300) and ``auto_device_data`` (2301), decoded by
``brping.PingMessage`` with the field layout of ``brping.definitions``: ``angle`` in gradians
(0-399), ``sample_period`` in ticks of 25 ns, ``number_of_samples`` (200-1200 on the Ping360),
``data`` the intensities (uint8, nearest first). Sample ``i`` (0-based) is bin ``i`` at range
``(i + 1) * bin_size_m`` with ``bin_size_m = speed_of_sound * sample_period * 25 ns / 2``
(:func:`sample_spacing_m`; Ping Viewer's ``Ping360::range()`` is that of the last sample), the
speed of sound a setting (:data:`SPEED_OF_SOUND_MPS`, 1500 m/s, as Ping Viewer's default).

Angle sense: Ping Viewer adds the vehicle's MAVLink yaw (NED, clockwise seen from above) to the
head angle to draw a north-up sonar (``Ping360::angle()`` in ``src/sensor/ping360.h``,
``_heading`` in ``src/sensor/ping360.cpp``) and draws angle 0 straight up and the angle growing
clockwise (``qml/Ping360Visualizer.qml``): the head angle grows clockwise seen from above, from
the head's own zero (drawn as the vehicle's forward when the head is mounted straight). So ``[sonar] angle_sense = -1`` (the default) for a head mounted
upright; a head mounted upside down turns the other way (``angle_sense = +1``), and where its
zero points in the body is ``[mounting.sonar] yaw_deg``.

The rest of a run:

* ``sonarslam.toml`` beside the ``.bin``: the calibration (without one, neutral mountings, as for
  any source that is not the marina), and a ``[ping360]`` table (:class:`Ping360Settings`):
  ``nav`` (the navigation, relative to the file), ``speed_of_sound_mps``, ``utc_offset_h`` (the
  file name's clock: local time, UTC + this), ``start`` (an ISO 8601 date and time that replaces
  the file name's), ``stamps``;
* the navigation: a ROS bag (its DVL, IMU and optional GPS topics, read by
  :func:`sonarslam.datasets.rosbag.read_roles`; a sonar topic in it is not read) or a CSV
  (:func:`read_nav_csv`).

Segments. The user changes the range (Ping Viewer opens at 2 m; every log is set to 15 or
60 m in its first seconds: ``Ping360::set_range`` keeps 1200 samples and changes the sample
period), the gain or the sector during a log. The beams are read as segments
(:class:`~sonarslam.datasets.records.SonarSegment`): runs of one sample count, sample period,
``gain_setting`` and, for ``auto_device_data``, sector (start, stop, step), each beam with its
own bin size (``BeamSeries.bin_size_m``) and its row padded with zeros to the most samples of
the log. The head's ``n_bins`` is that most, its ``bin_size_m`` the farthest-reaching
segment's (the Hough grid spans its range; a ``sonarslam.toml`` that says otherwise is an
error); its step is the median change of angle between beams and its beam width the Ping360's
2 deg (datasheet), unless ``sonarslam.toml`` sets them. ``sonarslam info`` lists the segments;
``--span T0,T1`` takes part of a log.

Bad logs: a file that is not a Ping Viewer log, a record whose lengths are not a record's, a
stamp that is not ``hh:mm:ss.zzz`` or jumps back more than :data:`BACK_JUMP_S` (less than 12 h),
a log without a beam: a :class:`DataError` naming the file, the record's index and its byte
offset. Bytes that form no message are dropped and counted by cause (:class:`_Framer`: a
message cut short, a wrong checksum, stray bytes, a message the log ends inside; their bytes
``ping360_dropped_bytes``), and so are whole messages of an id the protocol does not define
and beams whose data does not match their sample count or whose angle is not 0-399
(``ping360_*``), each cause with a :class:`DataWarning` naming it and its first record; a log
cut inside its last record: the record dropped, a warning. A change of the head's
``gain_setting`` during the log (the intensities change with it; the line extraction's
thresholds hold for one gain): a segment, counted (``ping360_gain_changes``) and a warning
naming the first (time, record, from and to).
"""

from __future__ import annotations

import array
import csv
import io
import math
import re
import struct
import tomllib
import unicodedata
import warnings
from collections import deque
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, replace
from datetime import UTC, datetime, timedelta, timezone
from pathlib import Path
from typing import IO, Any

import numpy as np
import tomli_w

from sonarslam.datasets.arrays import degrees_row, gated_dataset
from sonarslam.datasets.config import DatasetConfig, load_dataset_config
from sonarslam.datasets.dataset import (
    NEUTRAL_CALIBRATION,
    Dataset,
    neutral_warning,
    read_truth,
)
from sonarslam.datasets.errors import DataError, DataWarning
from sonarslam.datasets.gates import (
    SensorReport,
    check_heading_sense,
    gate_beams,
    navigation_span_s,
)
from sonarslam.datasets.geodesy import geodetic_to_local_en
from sonarslam.datasets.logfile import open_regular, read_text
from sonarslam.datasets.navlog import is_nav_log, navigation, navlog_settings, read_nav_log
from sonarslam.datasets.records import (
    STEP_TOLERANCE,
    AttitudeSeries,
    BeamSeries,
    DvlSeries,
    GpsSeries,
    SonarSegment,
    farthest_segment,
)
from sonarslam.datasets.rosbag import TOPIC_PRESETS, is_bag, read_roles
from sonarslam.datasets.toml import toml_file_line
from sonarslam.settings import SettingError, bounded, check_fields, one_of

__all__ = [
    "LOG_HEADER",
    "DEVICE_DATA",
    "AUTO_DEVICE_DATA",
    "SPEED_OF_SOUND_MPS",
    "TICK_S",
    "PING360_BEAM_WIDTH_DEG",
    "NAV_CSV_COLUMNS",
    "Ping360Settings",
    "Ping360Log",
    "is_ping360_log",
    "sample_spacing_m",
    "ascii_digits",
    "STILL_HEAD",
    "log_start_from_name",
    "read_ping360_log",
    "ping360_table",
    "ping360_settings",
    "read_nav_csv",
    "open_ping360",
    "write_ping360_log",
    "log_file_name",
]

#: The header string of a Ping Viewer log (``LogSensorStruct::_validHeader``).
LOG_HEADER = "PingViewer sensor log file"
#: The log versions this reader knows (``LogSensorStruct::_actualVersion``).
LOG_VERSIONS = (1,)
#: ping-protocol ids of the Ping360's beams.
DEVICE_DATA = 2300
AUTO_DEVICE_DATA = 2301
#: Speed of sound (m/s) unless ``[ping360] speed_of_sound_mps`` says otherwise (Ping Viewer's
#: default, ``Ping360::_viewerDefaultSpeedOfSound``).
SPEED_OF_SOUND_MPS = 1500.0
#: One tick of ``sample_period`` (s).
TICK_S = 25e-9
#: The Ping360's horizontal beam width (deg, Blue Robotics' datasheet).
PING360_BEAM_WIDTH_DEG = 2.0
GRADIANS_PER_TURN = 400
#: A beam stamp earlier than the one before by more than this (s, and less than 12 h) is a
#: clock jump: an error; less is counted (``ping360_out_of_order``) and sorted.
BACK_JUMP_S = 1.0
#: Longest record accepted (bytes): Ping Viewer logs what its link read at once, a fraction of
#: a second of the head's output; more is a corrupt length.
MAX_RECORD_BYTES = 1 << 24
#: Longest record stamp accepted (bytes): ``hh:mm:ss.zzz``, 12 characters of up to 4 bytes.
MAX_STAMP_BYTES = 48
#: Beams this far (s) before or after the navigation's span: the file name read in the wrong
#: time zone (an error saying so).
ZONE_MISS_S = 900.0
#: Civil time zones lie within this many hours of UTC (UTC-12 to UTC+14).
MAX_ZONE_H = 14.0
#: Zones are whole quarter hours from UTC; a miss farther than this (h) from one is not a zone:
#: 5 min, a few minutes of loggers started apart, while a third of arbitrary offsets are
#: farther from the nearest quarter hour.
ZONE_STEP_H = 0.25
ZONE_SLACK_H = 5.0 / 60.0
_DAY_MS = 86_400_000
_NULL = 0xFFFFFFFF
_U32 = struct.Struct(">I")
_I32 = struct.Struct(">i")
_FRAME = struct.Struct("<2sHHBB")
#: A record's stamp, its digits made ASCII first (:func:`ascii_digits`).
_STAMP = re.compile(r"([0-9]{2}):([0-5][0-9]):([0-5][0-9])\.([0-9]{3})")
#: ``yyyyMMdd-hhmmsszzz`` in a file name (``FileManager::_fileName``), its digits made ASCII.
_NAME = re.compile(r"([0-9]{8})-([0-9]{9})")
STAMP_KINDS = ("auto", "elapsed", "time_of_day")


@dataclass(frozen=True)
class Ping360Settings:
    """The ``[ping360]`` table of a ``.bin``'s ``sonarslam.toml``.

    Attributes
    ----------
    nav : tuple of str
        The navigation: a ROS bag, a CSV (:func:`read_nav_csv`) or the vehicle's own logs
        (:mod:`sonarslam.datasets.navlog`), one file or several (as ``--nav`` repeated: the
        DVL from one, the heading from another), each relative to the ``sonarslam.toml``; in
        TOML a file name or a list of them; () none (then ``--nav``).
    speed_of_sound_mps : float
        Speed of sound in the water (m/s): ``bin_size_m`` follows from it.
    utc_offset_h : float
        The file name's clock is UTC plus this (h): Ping Viewer names a log in the computer's
        local time.
    start : str
        An ISO 8601 date and time (``2024-05-02T10:31:07.250+02:00``; without an offset,
        ``utc_offset_h`` applies) that replaces the file name's; "" none.
    stamps : str
        ``"elapsed"`` (time since the log was opened, Ping Viewer since 2019),
        ``"time_of_day"`` (older logs) or ``"auto"`` (module docstring).
    """

    nav: tuple[str, ...] = ()
    speed_of_sound_mps: float = bounded(SPEED_OF_SOUND_MPS, 1300.0, 1700.0)
    utc_offset_h: float = bounded(0.0, -14.0, 14.0)
    start: str = ""
    stamps: str = one_of("auto", *STAMP_KINDS)

    def __post_init__(self) -> None:
        check_fields(self)


def is_ping360_log(path: str | Path) -> bool:
    """A ``.bin`` file (a Ping Viewer log, by its suffix: its content is checked on reading)."""
    p = Path(path)
    return p.suffix.lower() == ".bin" and p.is_file()


def sample_spacing_m(sample_period_ticks: int, speed_of_sound_mps: float) -> float:
    """Range between consecutive samples (m): sound's two-way travel in one sample period."""
    return speed_of_sound_mps * (sample_period_ticks * TICK_S) / 2.0


def ascii_digits(text: str) -> str:
    """``text`` with every Unicode decimal digit (``str.isdecimal``: the ASCII ones, and those of
    other scripts, as the Extended Arabic-Indic U+06F0-U+06F9 a Persian-locale Windows writes)
    made its ASCII digit (``unicodedata.decimal``); every other character kept.

    Qt 5 formats a ``QTime`` or ``QDateTime`` with a format string in the system locale
    (``QLocale::system()``, with the locale's own digits), and Ping Viewer names its logs and
    stamps its records so (``FileManager::createFileName``, ``FileLink::writeData``)."""
    if text.isascii():
        return text
    return "".join(str(unicodedata.decimal(c)) if c.isdecimal() else c for c in text)


def log_start_from_name(path: str | Path, utc_offset_h: float = 0.0) -> int:
    """The date and time in a Ping Viewer log's name (``yyyyMMdd-hhmmsszzz``, in any script's
    decimal digits: :func:`ascii_digits`) as Unix ms, the name's clock being UTC +
    ``utc_offset_h``; a :class:`DataError` naming the file when its name holds none."""
    p = Path(path)
    found = _NAME.search(ascii_digits(p.stem))
    when = None
    if found is not None:
        try:
            when = datetime.strptime(found.group(1) + found.group(2) + "000", "%Y%m%d%H%M%S%f")
        except ValueError:
            when = None
    if when is None:
        raise DataError(
            p,
            None,
            "the file name holds no Ping Viewer date and time (yyyyMMdd-hhmmsszzz.bin, e.g."
            " 20211223-132558123.bin), and the log has none else: rename the file, or give"
            ' [ping360] start = "2021-12-23T13:25:58.123+00:00" in sonarslam.toml beside it',
        )
    zone = timezone(timedelta(hours=utc_offset_h))
    return _unix_ms(when.replace(tzinfo=zone))


def _unix_ms(when: datetime) -> int:
    delta = when - datetime(1970, 1, 1, tzinfo=UTC)
    return (delta.days * 86_400 + delta.seconds) * 1000 + delta.microseconds // 1000


def _start_ms(path: Path, settings: Ping360Settings, where: Path) -> int:
    """The log's start (Unix ms): ``[ping360] start``, else the file name's."""
    if not settings.start:
        return log_start_from_name(path, settings.utc_offset_h)
    try:
        when = datetime.fromisoformat(settings.start)
    except ValueError:
        raise DataError(
            where,
            None,
            f"[ping360] start = {settings.start!r} is not an ISO 8601 date and time"
            " (2021-12-23T13:25:58.123+00:00)",
        ) from None
    if when.tzinfo is None:
        when = when.replace(tzinfo=timezone(timedelta(hours=settings.utc_offset_h)))
    return _unix_ms(when)


# -- reading the log -------------------------------------------------------------------------


class _Stream:
    """A log's bytes read in order, with the offset of the next byte."""

    def __init__(self, fh: IO[bytes], path: Path, size: int) -> None:
        self.fh = fh
        self.path = path
        self.size = size
        self.offset = 0

    def take(self, n: int) -> bytes | None:
        """``n`` bytes, or None when the file ends first."""
        data = self.fh.read(n)
        self.offset += len(data)
        return data if len(data) == n else None


def _header(s: _Stream) -> str:
    """Read the header; the strings' encoding (``"utf-16-be"`` or ``"utf-8"``)."""
    p = s.path
    if s.size == 0:
        raise DataError(p, None, "an empty file, not a Ping Viewer log")
    raw = s.take(4)
    n = _U32.unpack(raw)[0] if raw is not None else None
    text = s.take(n) if n is not None and n <= 4 * len(LOG_HEADER) else None
    encoding = ""
    if text is not None:
        for enc in ("utf-16-be", "utf-8"):
            try:
                if text.decode(enc) == LOG_HEADER:
                    encoding = enc
            except UnicodeDecodeError:
                pass
    if not encoding:
        raise DataError(
            p, None, f"not a Ping Viewer log: it does not start with the string {LOG_HEADER!r}"
        )
    raw = s.take(4)
    version = _I32.unpack(raw)[0] if raw is not None else None
    if version not in LOG_VERSIONS:
        raise DataError(
            p, None, f"Ping Viewer log version {version}: this reader knows {LOG_VERSIONS}"
        )
    for what in ("hash", "date", "tag", "OS name", "OS version"):
        raw = s.take(4)
        n = _U32.unpack(raw)[0] if raw is not None else None
        if n is None or (n != _NULL and (n > 1024 or s.take(n) is None)):
            raise DataError(
                p, None, f"the header's Ping Viewer {what} (byte {s.offset}) is not a string"
            )
    if s.take(8) is None:
        raise DataError(p, None, "the header ends before its sensor family and type")
    return encoding


@dataclass(frozen=True)
class _Record:
    index: int  # 0-based, in the file
    offset: int  # byte offset of the record in the file
    stamp_ms: int  # the stamp, ms since midnight of its (elapsed or local) clock
    data: bytes  # the bytes the link read at once: parts of messages, whole ones, several


def _stamp_ms(s: _Stream, index: int, offset: int, raw: bytes, encoding: str) -> int:
    try:
        text: str | bytes = raw.decode(encoding)
    except UnicodeDecodeError:
        text = raw
    found = _STAMP.fullmatch(ascii_digits(text)) if isinstance(text, str) else None
    if found is None:
        raise DataError(
            s.path,
            None,
            f"record {index} (byte offset {offset}): time stamp {text[:32]!r} is not"
            " hh:mm:ss.zzz (in decimal digits of any script)",
        )
    h, m, sec, ms = (int(g) for g in found.groups())
    return ((h * 60 + m) * 60 + sec) * 1000 + ms


def _records(s: _Stream, encoding: str, counts: dict[str, int]) -> Iterator[_Record]:
    """The records after the header, one at a time (module docstring for what ends them)."""
    index = 0
    while s.offset < s.size:
        offset = s.offset
        raw = s.take(4)
        n = _U32.unpack(raw)[0] if raw is not None else None
        if n is not None and n in (0, _NULL):
            if s.size - s.offset > 0:
                left = s.size - offset
                warnings.warn(
                    f"{s.path}: record {index} (byte offset {offset}) has no time stamp (Ping"
                    " Viewer writes none after 24 h of logging, and stops reading there): the"
                    f" {left} bytes from it on are not read",
                    DataWarning,
                    stacklevel=4,
                )
                counts["ping360_unread_bytes"] = left
            return
        if n is not None and n > MAX_STAMP_BYTES:
            raise DataError(
                s.path,
                None,
                f"record {index} (byte offset {offset}): a time stamp of {n} bytes, not the"
                f" {MAX_STAMP_BYTES} at most of hh:mm:ss.zzz (a corrupt log)",
            )
        stamp = s.take(n) if n is not None else None
        raw = s.take(4) if stamp is not None else None
        size = _U32.unpack(raw)[0] if raw is not None else None
        if size is not None and size != _NULL and size > MAX_RECORD_BYTES:
            raise DataError(
                s.path,
                None,
                f"record {index} (byte offset {offset}): a record of {size} bytes, more than the"
                f" {MAX_RECORD_BYTES} Ping Viewer reads from its link at once (a corrupt log)",
            )
        data = b"" if size == _NULL else (s.take(size) if size is not None else None)
        if stamp is None or data is None:
            warnings.warn(
                f"{s.path}: the log ends inside record {index} (byte offset {offset}): the"
                " record is dropped",
                DataWarning,
                stacklevel=4,
            )
            counts["ping360_truncated_records"] = 1
            return
        yield _Record(index, offset, _stamp_ms(s, index, offset, stamp, encoding), data)
        index += 1


_LENGTH_ID = struct.Struct("<HH")
_START = b"BR"


class _Framer:
    """The ping-protocol messages of a log's byte stream, fed a record at a time.

    A record holds what Ping Viewer's link read at once (``SerialLink``: ``readAll()`` on
    ``readyRead``, logged by ``FileLink::writeData``), not a message: one message's bytes may
    straddle records and a record may hold several. So the records' bytes are one stream,
    framed as ``brping.PingParser`` frames it: ``"BR"``, payload length, message id, source and
    destination ids, the payload, and a checksum (the sum of the bytes before it). Each
    message takes the record that holds its first byte (its stamp is the nearest to the
    ping). A start whose header no message of the protocol could have (a known id with
    another length) is not one; a frame whose checksum is wrong is searched again from its
    second byte, so that a message that begins inside it is found. Bytes that are in no
    message are dropped, by cause:

    ``cut_messages``
        a message whose bytes end before its length (the next message begins inside it: the
        link lost bytes);
    ``checksum_errors``
        a whole message whose checksum is wrong (its bytes changed on the way);
    ``stray_bytes``
        bytes before any message start (noise, or the end of a message the log began in);
    ``unfinished_messages``
        the log ends inside a message.
    """

    def __init__(self, payloads: dict[int, Any]) -> None:
        self.payloads = payloads
        self.buf = bytearray()
        self.base = 0  # stream position of buf[0]
        self.pieces: deque[tuple[int, _Record]] = deque()  # stream position of each record
        # the run of dropped bytes in progress: start, kind ("stray", "frame"), the failed
        # frame's end, the record of its first byte
        self.run: tuple[int, str, int, _Record] | None = None
        #: cause -> [occurrences, bytes]; cause -> the record of the first occurrence
        self.lost: dict[str, list[int]] = {}
        self.first: dict[str, _Record] = {}

    def _plausible(self, length: int, msg_id: int) -> bool:
        spec = self.payloads.get(msg_id)
        if spec is None:
            return True  # an id the protocol does not define: its checksum decides
        fixed = int(spec["payload_length"])
        return length >= fixed if "data" in spec["field_names"] else length == fixed

    def _record_at(self, position: int) -> _Record:
        """The record that holds the byte at stream ``position``."""
        found = self.pieces[0][1]
        for start, record in self.pieces:
            if start > position:
                break
            found = record
        return found

    def _count(self, cause: str, n_bytes: int, record: _Record) -> None:
        entry = self.lost.setdefault(cause, [0, 0])
        entry[0] += 1
        entry[1] += n_bytes
        self.first.setdefault(cause, record)

    def _lose(self, position: int, kind: str, frame_end: int = 0) -> None:
        """The byte at stream ``position`` is in no message: open a run of dropped bytes
        there (a failed frame ends a run of stray bytes and opens its own)."""
        if self.run is not None and not (kind == "frame" and self.run[1] == "stray"):
            return
        if self.run is not None:
            self._close(position)
        self.run = (position, kind, frame_end, self._record_at(position))

    def _close(self, position: int) -> None:
        """The run of dropped bytes ends at stream ``position`` (a message, or the end)."""
        if self.run is None:
            return
        start, kind, frame_end, record = self.run
        if kind == "stray":
            cause = "stray_bytes"
        else:
            cause = "cut_messages" if position < frame_end else "checksum_errors"
        self._count(cause, position - start, record)
        self.run = None

    def feed(self, record: _Record) -> list[tuple[_Record, bytes]]:
        """The messages that ``record``'s bytes complete, each with the record of its first
        byte."""
        buf = self.buf
        if record.data:
            self.pieces.append((self.base + len(buf), record))
            buf += record.data
        out: list[tuple[_Record, bytes]] = []
        pos = 0
        while len(buf) - pos >= 2:
            if buf[pos] != _START[0] or buf[pos + 1] != _START[1]:
                j = buf.find(_START, pos + 1)
                if j < 0:
                    j = len(buf) - 1 if buf[-1] == _START[0] else len(buf)
                self._lose(self.base + pos, "stray")
                pos = j
                continue
            if len(buf) - pos < 8:
                break
            length, msg_id = _LENGTH_ID.unpack_from(buf, pos + 2)
            if not self._plausible(length, msg_id):
                self._lose(self.base + pos, "stray")
                pos += 1
                continue
            end = pos + 10 + length
            if len(buf) < end:
                break
            if sum(buf[pos : end - 2]) & 0xFFFF == buf[end - 2] | buf[end - 1] << 8:
                self._close(self.base + pos)
                out.append((self._record_at(self.base + pos), bytes(buf[pos:end])))
                pos = end
            else:
                self._lose(self.base + pos, "frame", self.base + end)
                pos += 1
        del buf[:pos]
        self.base += pos
        while len(self.pieces) > 1 and self.pieces[1][0] <= self.base:
            self.pieces.popleft()
        return out

    def finish(self) -> None:
        """The end of the log: the bytes left are dropped (an open run, a message the log
        ends inside, stray bytes)."""
        end = self.base + len(self.buf)
        if self.run is not None:
            self._close(end)
        elif self.buf:
            record = self._record_at(self.base)
            head = bytes(self.buf[:8])
            starts = head.startswith(_START) or head == _START[:1]
            if starts and len(head) == 8:
                starts = self._plausible(*_LENGTH_ID.unpack_from(head, 2))
            self._count("unfinished_messages" if starts else "stray_bytes", len(self.buf), record)
        self.buf.clear()
        self.base = end


@dataclass(frozen=True)
class _Beam:
    angle_grad: int
    sample_period: int
    data: bytes
    gain_setting: int
    sector: tuple[int, int, int] | None  # auto_device_data's start, stop angles and step


def _payloads() -> dict[int, Any]:
    from brping import definitions  # lazy: only .bin logs load brping

    return definitions.payload_dict_all  # type: ignore[no-any-return]


def _decode(frame: bytes, payloads: dict[int, Any]) -> tuple[str, _Beam | None]:
    """What a message (a whole frame whose checksum holds) is (``"beam"``, ``"other"``, or the
    fault counted) and its beam."""
    from brping import PingMessage  # lazy: only .bin logs load brping

    msg_id = _LENGTH_ID.unpack_from(frame, 2)[1]
    if msg_id not in payloads:
        return "unknown_messages", None
    if msg_id not in (DEVICE_DATA, AUTO_DEVICE_DATA):
        return "other_messages", None
    if len(frame) - 10 < payloads[msg_id]["payload_length"]:
        return "bad_messages", None
    m = PingMessage(msg_data=frame)
    data = bytes(m.data)
    if m.data_length != len(data) or m.number_of_samples != len(data):
        return "bad_messages", None
    if not len(data):
        return "other_messages", None  # a reply without a transmission
    if not 0 <= m.angle < GRADIANS_PER_TURN or m.sample_period < 1:
        return "bad_messages", None
    sector = None
    if msg_id == AUTO_DEVICE_DATA:
        sector = (int(m.start_angle), int(m.stop_angle), int(m.num_steps))
    return "beam", _Beam(int(m.angle), int(m.sample_period), data, int(m.gain_setting), sector)


class _SampleRows:
    """The beams' samples, a row each, in an array grown as needed (by half again when full,
    and widened with zeros for a beam of more samples than any before)."""

    def __init__(self, rows: int, width: int) -> None:
        self.data = np.zeros((max(rows, 1), width), np.uint8)
        self.n = 0

    def append(self, samples: bytes) -> None:
        rows, width = self.data.shape
        if self.n == rows or len(samples) > width:
            grown = np.zeros(
                (rows + rows // 2 + 1 if self.n == rows else rows, max(width, len(samples))),
                np.uint8,
            )
            grown[: self.n, :width] = self.data[: self.n]
            self.data = grown
        row = self.data[self.n]
        row[: len(samples)] = np.frombuffer(samples, dtype=np.uint8)
        row[len(samples) :] = 0
        self.n += 1


@dataclass(frozen=True)
class Ping360Log:
    """The beams of a Ping Viewer log (:func:`read_ping360_log`).

    Attributes
    ----------
    beams : BeamSeries
        Times (Unix s), transducer angles (rad, ``gradians * pi / 200``), intensities
        ``(N, n_bins)`` uint8, nearest sample first, a beam of fewer samples padded with
        zeros; in time order. With segments of several bin sizes, each beam's own
        (``beams.bin_size_m``), else None.
    segments : tuple of SonarSegment
        The stretches of one range, gain and sector, in time order (module docstring).
    n_bins : int
        The most samples of a beam.
    sample_period_ticks : int
        ``sample_period`` of the segment that reaches farthest (25 ns ticks).
    bin_size_m : float
        :func:`sample_spacing_m` of it at the settings' speed of sound (m): the head's.
    step_grad : int
        Median change of angle between consecutive beams (gradians); 0 with one beam.
    start_ms : int
        The log's start (Unix ms): the stamps' zero (elapsed) or the start's midnight
        (time of day) is derived from it.
    stamps : str
        How the stamps were read: ``"elapsed"`` or ``"time_of_day"``.
    records : int
        Records read.
    counts : dict
        ``ping360_*`` counts: other messages, faults dropped and their bytes, gain changes
        (module docstring).
    encoding : str
        The log's strings: ``"utf-16-be"`` or ``"utf-8"``.
    """

    beams: BeamSeries
    segments: tuple[SonarSegment, ...]
    n_bins: int
    sample_period_ticks: int
    bin_size_m: float
    step_grad: int
    start_ms: int
    stamps: str
    records: int
    counts: dict[str, int]
    encoding: str


#: The counts of a log (``ping360_*``): messages, faults, and the bytes dropped.
_COUNTS = (
    "other_messages",
    "bad_messages",
    "unknown_messages",
    "checksum_errors",
    "cut_messages",
    "unfinished_messages",
    "stray_bytes",
    "dropped_bytes",
    "out_of_order",
    "midnight_wraps",
    "truncated_records",
    "gain_changes",
)


def read_ping360_log(
    path: str | Path, settings: Ping360Settings | None = None, where: Path | None = None
) -> Ping360Log:
    """Read the Ping360 beams of a Ping Viewer ``.bin`` log, streamed: the file is read a
    record at a time, its bytes framed into messages across records (:class:`_Framer`), the
    beams into one array sized from the file (module docstring for the layout, the times, the
    segments and the faults).

    Parameters
    ----------
    path : str or Path
    settings : Ping360Settings, optional
        Speed of sound, the file name's clock, a start that replaces it, how to read stamps.
    where : Path, optional
        The file that gave ``settings`` (for its errors).

    Raises
    ------
    DataError
        Naming the file, and the record's index and byte offset where there is one.
    """
    p = Path(path)
    settings = settings or Ping360Settings()
    payloads = _payloads()
    counts = {f"ping360_{k}": 0 for k in _COUNTS}
    first_fault: dict[str, _Record] = {}
    framer = _Framer(payloads)
    with open_regular(p) as fh:
        size = fh.seek(0, io.SEEK_END)
        fh.seek(0)
        s = _Stream(fh, p, size)
        encoding = _header(s)
        rows: _SampleRows | None = None
        grads = array.array("H")
        stamps = array.array("q")
        setting_of = array.array("I")  # each beam's index in settings_seen
        settings_seen: dict[tuple[int, int, int, tuple[int, int, int] | None], int] = {}
        records = 0
        wraps, last_ms = 0, -1
        first_stamp: int | None = None
        gain = -1
        first_gain: tuple[int, int, int, int] | None = None  # beam, record, from, to
        for record in _records(s, encoding, counts):
            records += 1
            if first_stamp is None:
                first_stamp = record.stamp_ms
            for at, frame in framer.feed(record):
                kind, beam = _decode(frame, payloads)
                if beam is None:
                    counts[f"ping360_{kind}"] += 1
                    first_fault.setdefault(kind, at)
                    continue
                if rows is None:
                    # beams are nearly all of a Ping360 log: as many rows as messages of this
                    # beam's size the rest of the file could hold (grown if a segment of
                    # fewer samples needs more)
                    smallest = 10 + 14 + 2 + len(beam.data)
                    rows = _SampleRows((size - at.offset) // smallest, len(beam.data))
                t_ms = at.stamp_ms + wraps * _DAY_MS
                if last_ms >= 0 and t_ms < last_ms:
                    if last_ms - t_ms > _DAY_MS // 2:
                        wraps += 1
                        t_ms += _DAY_MS
                        counts["ping360_midnight_wraps"] += 1
                    elif last_ms - t_ms > BACK_JUMP_S * 1000:
                        raise DataError(
                            p,
                            None,
                            f"record {at.index} (byte offset {at.offset}): its stamp is"
                            f" {(last_ms - t_ms) / 1000:.3f} s earlier than the beam before (a"
                            f" clock jump beyond {BACK_JUMP_S:g} s)",
                        )
                    else:
                        counts["ping360_out_of_order"] += 1
                last_ms = max(last_ms, t_ms)
                if gain >= 0 and beam.gain_setting != gain:
                    counts["ping360_gain_changes"] += 1
                    if first_gain is None:
                        first_gain = (rows.n, at.index, gain, beam.gain_setting)
                gain = beam.gain_setting
                key = (len(beam.data), beam.sample_period, beam.gain_setting, beam.sector)
                if key not in settings_seen:
                    settings_seen[key] = len(settings_seen)
                setting_of.append(settings_seen[key])
                rows.append(beam.data)
                grads.append(beam.angle_grad)
                stamps.append(t_ms)
        framer.finish()
    for cause, (occurrences, n_bytes) in framer.lost.items():
        counts[f"ping360_{cause}"] = n_bytes if cause == "stray_bytes" else occurrences
        counts["ping360_dropped_bytes"] += n_bytes
    if rows is None or first_stamp is None:
        found = ", ".join(f"{k} {v}" for k, v in counts.items() if v) or "no record"
        raise DataError(
            p, None, f"no Ping360 beam (device_data 2300, auto_device_data 2301): {found}"
        )
    _warn_faults(p, counts, first_fault, framer)
    start_ms = _start_ms(p, settings, where or p)
    kind = settings.stamps
    if kind == "auto":
        tod = (start_ms + int(round(settings.utc_offset_h * 3_600_000))) % _DAY_MS
        near_clock = abs(first_stamp - tod) < first_stamp
        kind = "time_of_day" if near_clock else "elapsed"
    base_ms = start_ms
    if kind == "time_of_day":
        local_ms = start_ms + int(round(settings.utc_offset_h * 3_600_000))
        base_ms = start_ms - local_ms % _DAY_MS  # the start's (local) midnight
    n = rows.n
    unix_ms = np.frombuffer(stamps, dtype=np.int64) + base_ms
    order = np.argsort(unix_ms, kind="stable")
    if not counts["ping360_out_of_order"]:
        order = np.arange(n)
    keys = list(settings_seen)
    setting = np.frombuffer(setting_of, dtype=np.uint32)[order]
    bin_m = np.array([sample_spacing_m(k[1], settings.speed_of_sound_mps) for k in keys])
    t_s = (unix_ms[order] / 1000.0).astype(np.float64)
    beams = BeamSeries(
        t_s,
        (np.frombuffer(grads, dtype=np.uint16)[order] * (math.pi / 200.0)).astype(np.float64),
        rows.data[:n][order] if counts["ping360_out_of_order"] else rows.data[:n],
        False,
        bin_m[setting] if np.unique(bin_m[setting]).size > 1 else None,
    )
    segments = _segments(t_s, setting, keys, bin_m)
    farthest = farthest_segment(segments)
    far = next(
        k
        for k, key in enumerate(keys)
        if (key[0], bin_m[k]) == (farthest.n_bins, farthest.bin_size_m)
    )
    if counts["ping360_out_of_order"]:
        warnings.warn(
            f"{p}: {counts['ping360_out_of_order']} beam(s) stamped earlier than the one before,"
            " sorted by stamp",
            DataWarning,
            stacklevel=2,
        )
    if first_gain is not None:
        i, index, before, after = first_gain
        warnings.warn(
            f"{p}: the head's gain_setting changed {counts['ping360_gain_changes']} time(s)"
            f" during the log, the first at t={unix_ms[i] / 1000.0:.3f} s (record {index}):"
            f" {_gain_name(before)} -> {_gain_name(after)}; the echoes' intensities change"
            " with it while the line extraction's thresholds ([features]) hold for one gain, so"
            " lines may vanish or multiply across the change: the log is read as segments"
            " (sonarslam info lists them); take one gain's with --span T0,T1",
            DataWarning,
            stacklevel=2,
        )
    return Ping360Log(
        beams=beams,
        segments=segments,
        n_bins=int(rows.data.shape[1]),
        sample_period_ticks=keys[far][1],
        bin_size_m=float(bin_m[far]),
        step_grad=_step_grad(np.frombuffer(grads, dtype=np.uint16)),
        start_ms=start_ms,
        stamps=kind,
        records=records,
        counts=counts,
        encoding=encoding,
    )


def _said(key: tuple[int, int, int, tuple[int, int, int] | None]) -> str:
    """A beam setting in words: its sample period, gain and (auto_device_data) sector."""
    n, period, gain, sector = key
    words = f"sample period {period} ticks, gain {_gain_name(gain)}"
    if sector is not None:
        start, stop, step = sector
        words += f", scanning {start}-{stop} gradians by {step}"
    return words


def _segments(
    t_s: np.ndarray,
    setting: np.ndarray,
    keys: list[tuple[int, int, int, tuple[int, int, int] | None]],
    bin_m: np.ndarray,
) -> tuple[SonarSegment, ...]:
    """The runs of beams of one setting, in time order."""
    cuts = np.flatnonzero(np.diff(setting.astype(np.int64))) + 1
    starts = np.r_[0, cuts]
    ends = np.r_[cuts, setting.size]
    out = []
    for a, b in zip(starts, ends, strict=True):
        k = int(setting[a])
        out.append(
            SonarSegment(
                t0_s=float(t_s[a]),
                t1_s=float(t_s[b - 1]),
                beams=int(b - a),
                n_bins=keys[k][0],
                bin_size_m=float(bin_m[k]),
                setting=_said(keys[k]),
            )
        )
    return tuple(out)


#: The Ping360's ``gain_setting`` values (ping-protocol ``device_data``).
PING360_GAINS = {0: "low", 1: "normal", 2: "high"}


def _gain_name(gain: int) -> str:
    return f"{gain} ({PING360_GAINS.get(gain, 'not a Ping360 gain')})"


def _step_grad(grads: np.ndarray) -> int:
    """Median absolute change of angle between consecutive beams (gradians, wrapped)."""
    if grads.size < 2:
        return 0
    d = np.mod(np.diff(grads.astype(np.int64)), GRADIANS_PER_TURN)
    d = np.minimum(d, GRADIANS_PER_TURN - d)
    d = d[d > 0]
    return int(np.median(d)) if d.size else 0


#: The faults of a log in words (``ping360_<fault>``): what was dropped, and why.
_FAULTS = {
    "cut_messages": "message(s) cut short, dropped: their bytes end before their length (the"
    " next message begins inside them: the link lost bytes)",
    "checksum_errors": "message(s) with a wrong checksum, dropped (their bytes changed on the"
    " link)",
    "unfinished_messages": "message the log ends inside, dropped",
    "stray_bytes": "byte(s) outside any message, dropped (noise on the link, or the end of a"
    " message the log began in)",
    "bad_messages": "Ping360 beam message(s) whose fields disagree (sample count, data length"
    " or angle), dropped",
    "unknown_messages": "message(s) of an id the ping protocol does not define, dropped",
}


def _warn_faults(
    p: Path, counts: dict[str, int], first: dict[str, _Record], framer: _Framer
) -> None:
    for kind, what in _FAULTS.items():
        n = counts[f"ping360_{kind}"]
        if not n:
            continue
        r = first.get(kind) or framer.first[kind]
        lost = framer.lost.get(kind)
        size = f" ({lost[1]} bytes)" if lost is not None and kind != "stray_bytes" else ""
        warnings.warn(
            f"{p}: {n} {what}{size}; the first in record {r.index} (byte offset {r.offset})",
            DataWarning,
            stacklevel=3,
        )


# -- the navigation ----------------------------------------------------------------------------

#: The columns of a navigation CSV (header row required; any order; ``t_s`` and at least the
#: DVL's and the AHRS's): name -> what it holds. A row holds the sensors sampled at its time:
#: an empty cell is no sample.
NAV_CSV_COLUMNS = {
    "t_s": "time (Unix s, the sonar's clock)",
    "dvl_vx_mps": "DVL bottom velocity along the DVL frame's x (m/s)",
    "dvl_vy_mps": "DVL bottom velocity along the DVL frame's y (m/s)",
    "dvl_valid": "1 with bottom lock, 0 without (optional column; default 1)",
    "ahrs_yaw_enu_rad": "AHRS yaw, counter-clockwise from East (rad; REP-103 ENU; from a NED"
    " heading psi: pi/2 - psi)",
    "ahrs_yaw_rate_rad_per_s": "gyro z rate, counter-clockwise (rad/s; optional column)",
    "gps_lat_deg": "WGS-84 latitude (deg; optional: a ruler, never an input)",
    "gps_lon_deg": "WGS-84 longitude (deg)",
}
_NAV_GROUPS = {
    "dvl": ("dvl_vx_mps", "dvl_vy_mps"),
    "ahrs": ("ahrs_yaw_enu_rad",),
    "gps": ("gps_lat_deg", "gps_lon_deg"),
}
_NAV_OPTIONAL = {"dvl_valid": "dvl", "ahrs_yaw_rate_rad_per_s": "ahrs"}


def read_nav_csv(
    path: str | Path,
) -> tuple[DvlSeries, AttitudeSeries, GpsSeries | None]:
    """The DVL, the AHRS and an optional GPS of a navigation CSV (:data:`NAV_CSV_COLUMNS`).

    Raises
    ------
    DataError
        Naming the file and the line: a missing or unknown column, a row of another number of
        cells, a cell that is not a finite number, half a sensor's cells, a sensor's time earlier
        than its row before, a latitude or longitude out of range, no DVL or AHRS row, a yaw
        in degrees (:func:`sonarslam.datasets.arrays.degrees_row`: its first row beyond 2 pi,
        or a wrap of 360), a heading that turns against its gyro's rate (NED beside ENU:
        :func:`sonarslam.datasets.gates.check_heading_sense`).
    """
    p = Path(path)
    out: dict[str, array.array[float]] = {g: array.array("d") for g in _NAV_GROUPS}
    with open_regular(p) as fh:
        text = io.TextIOWrapper(fh, encoding="utf-8", newline="")
        rows = csv.reader(text)
        try:
            _nav_rows(p, rows, out)
        except UnicodeDecodeError:
            read_text(p, "utf-8")  # the error again, with the line of the byte
            raise DataError(p, None, "not UTF-8 text") from None
        except csv.Error as exc:
            raise DataError(p, rows.line_num, f"not a CSV row: {exc}") from None
        finally:
            text.detach()
    for group in ("dvl", "ahrs"):
        if not out[group]:
            raise DataError(p, None, f"no {group.upper()} row")
    dvl = np.frombuffer(out["dvl"]).reshape(-1, 4)
    ahrs = np.frombuffer(out["ahrs"]).reshape(-1, 4)
    degrees = degrees_row(ahrs[:, 1], unwrapped=True)
    if degrees is not None:
        i, why = degrees
        raise DataError(
            p,
            int(ahrs[i, 3]),
            f"ahrs_yaw_enu_rad = {ahrs[i, 1]:g} {why}: degrees? (the column is radians)",
        )
    rate: np.ndarray = ahrs[:, 2]
    if np.isnan(rate).any():
        if not np.isnan(rate).all():
            raise DataError(p, None, "ahrs_yaw_rate_rad_per_s: every AHRS row, or none")
        t_a = ahrs[:, 0]
        rate = (
            np.gradient(np.unwrap(ahrs[:, 1]), t_a)
            if t_a.size > 1 and np.all(np.diff(t_a) > 0)
            else np.zeros(t_a.size)
        )
    else:
        check_heading_sense(
            p,
            "ahrs_yaw_enu_rad turns against ahrs_yaw_rate_rad_per_s",
            ahrs[:, 0],
            ahrs[:, 1],
            rate,
        )
    gps = None
    if out["gps"]:
        g = np.frombuffer(out["gps"]).reshape(-1, 3)
        lat0, lon0 = float(g[0, 1]), float(g[0, 2])
        en = geodetic_to_local_en(g[:, 1], g[:, 2], lat0, lon0)
        gps = GpsSeries(g[:, 0].copy(), en, (lat0, lon0), None, p)
    return (
        DvlSeries(
            dvl[:, 0].copy(), dvl[:, 1:3].copy(), dvl[:, 3] > 0.5, np.full(len(dvl), np.nan), p
        ),
        AttitudeSeries(ahrs[:, 0].copy(), ahrs[:, 1].copy(), np.asarray(rate, float).copy(), p),
        gps,
    )


def _nav_rows(p: Path, rows: Any, out: dict[str, array.array[float]]) -> None:
    """The rows of a navigation CSV (``csv.reader``) into ``out``: per sensor, its rows
    flattened (DVL: t, vx, vy, valid; AHRS: t, yaw, rate or NaN, line; GPS: t, lat, lon)."""
    try:
        header = [h.strip() for h in next(rows)]
    except StopIteration:
        raise DataError(p, None, "an empty file: a navigation CSV needs a header row") from None
    unknown = [h for h in header if h not in NAV_CSV_COLUMNS]
    if unknown or len(set(header)) != len(header):
        raise DataError(
            p,
            1,
            f"header: unknown or repeated column(s) {unknown or header}; the columns are"
            f" {list(NAV_CSV_COLUMNS)} (docs/data.md)",
        )
    need = ["t_s", *_NAV_GROUPS["dvl"], *_NAV_GROUPS["ahrs"]]
    missing = [h for h in need if h not in header]
    gps_cols = [h for h in _NAV_GROUPS["gps"] if h in header]
    if missing or len(gps_cols) == 1:
        raise DataError(p, 1, f"header: missing column(s) {missing or list(_NAV_GROUPS['gps'])}")
    col = {h: i for i, h in enumerate(header)}
    last = {"dvl": -math.inf, "ahrs": -math.inf, "gps": -math.inf}
    for cells in rows:
        number = rows.line_num
        if not cells or all(not c.strip() for c in cells):
            continue
        if len(cells) != len(header):
            raise DataError(p, number, f"{len(cells)} cells, the header has {len(header)}")
        values: dict[str, float | None] = {}
        for h, i in col.items():
            cell = cells[i].strip()
            if not cell:
                values[h] = None
                continue
            try:
                v = float(cell)
            except ValueError:
                v = math.nan
            if not math.isfinite(v):
                raise DataError(p, number, f"{h} = {cell!r} is not a finite number")
            values[h] = v
        t = values["t_s"]
        if t is None:
            raise DataError(p, number, "t_s is empty")
        for group, names in _NAV_GROUPS.items():
            got = [values.get(h) for h in names]
            extra = [
                h for h, g in _NAV_OPTIONAL.items() if g == group and values.get(h) is not None
            ]
            if all(v is None for v in got):
                if extra:
                    raise DataError(p, number, f"{extra[0]} without {', '.join(names)}")
                continue
            if any(v is None for v in got):
                raise DataError(p, number, f"{', '.join(names)} go together: one is empty")
            if t < last[group]:
                raise DataError(
                    p,
                    number,
                    f"t_s {t:.6f} is earlier than the {group}'s row before ({last[group]:.6f})",
                )
            last[group] = t
            row = [t, *(float(v) for v in got if v is not None)]
            if group == "dvl":
                valid = values.get("dvl_valid")
                if valid is not None and valid not in (0.0, 1.0):
                    raise DataError(p, number, f"dvl_valid = {valid:g} is not 0 or 1")
                row.append(1.0 if valid is None else valid)
            elif group == "ahrs":
                rate_cell = values.get("ahrs_yaw_rate_rad_per_s")
                row.extend((math.nan if rate_cell is None else rate_cell, float(number)))
            elif abs(row[1]) > 90.0 or abs(row[2]) > 180.0:
                raise DataError(p, number, "gps_lat_deg or gps_lon_deg out of range")
            out[group].extend(row)


def _bag_navigation(
    bag: Path, topics_file: str | Path | None
) -> tuple[DvlSeries, AttitudeSeries, GpsSeries | None, dict[str, int]]:
    """The DVL, IMU and GPS roles of a ROS bag (its sonar topics are not read)."""
    read = read_roles(
        bag, ("dvl", "imu", "gps"), ("dvl", "imu"), topics_file, " of the Ping360's navigation"
    )
    assert read.dvl is not None and read.attitude is not None
    counts = {k: v for k, v in read.counts.items() if k.endswith("_out_of_order")}
    return read.dvl, read.attitude, read.gps, counts


def _nav_paths(
    nav: str | Path | Sequence[str | Path] | None, settings: Ping360Settings
) -> tuple[Path, ...]:
    """The navigation files: ``--nav`` (one or several), else ``[ping360] nav``."""
    if nav is None:
        return tuple(Path(n) for n in settings.nav)
    if isinstance(nav, (str, Path)):
        return (Path(nav),)
    return tuple(Path(n) for n in nav)


def _navigation(
    navs: tuple[Path, ...],
    topics_file: str | Path | None,
    config: DatasetConfig,
    tomls: tuple[Path | str | None, ...],
) -> tuple[DvlSeries, AttitudeSeries, GpsSeries | None, dict[str, int], DatasetConfig, str]:
    """The DVL, AHRS and GPS of the navigation, its counts, the configuration (a BlueROV2's
    log may set the DVL's frame and noise: :func:`sonarslam.datasets.navlog.navigation`) and
    what was taken from which file ("" for a bag or a navigation CSV)."""
    nav = navs[0]
    if len(navs) == 1 and not is_nav_log(nav):
        if is_bag(nav):
            return (*_bag_navigation(nav, topics_file), config, "")
        if nav.suffix.lower() == ".csv":
            if topics_file is not None:
                raise DataError(
                    Path(topics_file), None, "--topics is for a navigation bag, not a CSV"
                )
            dvl, att, gps = read_nav_csv(nav)
            return dvl, att, gps, {}, config, ""
        if not nav.exists():
            raise DataError(nav, None, "the Ping360's navigation: no such file or bag")
        raise DataError(
            nav,
            None,
            "the Ping360's navigation must be a ROS bag (.bag, .mcap, a bag directory), a .csv,"
            " or a BlueROV2's own log (.tlog, ArduSub dataflash .bin, DVL A50 JSON,"
            " QGroundControl CSV)",
        )
    settings = navlog_settings(*tomls)
    found = navigation([read_nav_log(n, settings) for n in navs], config, settings)
    return found.dvl, found.attitude, found.gps, found.counts, found.config, found.said


# -- the dataset ---------------------------------------------------------------------------------


def _table(path: Path) -> tuple[dict[str, Any], dict[str, Any]]:
    """``[ping360]`` and ``[sonar]`` of a ``sonarslam.toml`` (the file's own keys)."""
    try:
        data = tomllib.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError):
        return {}, {}  # load_dataset_config names what is wrong with the file
    ping, sonar = data.get("ping360", {}), data.get("sonar", {})
    if not isinstance(ping, dict):
        raise DataError(path, None, "[ping360] must be a table")
    return ping, sonar if isinstance(sonar, dict) else {}


def _nav_names(value: Any, path: Path) -> list[str]:
    """``[ping360] nav`` as a list of file names: a string ("" none) or a list of strings; a
    :class:`DataError` naming ``path`` for anything else."""
    names = [value] if isinstance(value, str) else value
    if not isinstance(names, list) or not all(isinstance(n, str) and n for n in names):
        raise DataError(
            path,
            None,
            f"[ping360] nav must be a file name or a list of file names (as --nav repeated:"
            f' nav = ["dvl.json", "attitude.tlog"]), got {value!r}',
        )
    return [n for n in names if n]


def _settings(table: dict[str, Any], path: Path, base: Ping360Settings) -> Ping360Settings:
    known = {"nav", "speed_of_sound_mps", "utc_offset_h", "start", "stamps"}
    unknown = sorted(set(table) - known)
    if unknown:
        raise DataError(
            path, None, f"unknown key(s) {unknown} in [ping360]; allowed: {sorted(known)}"
        )
    values = dict(table)
    for key in ("start", "stamps"):
        if key in values and not isinstance(values[key], str):
            raise DataError(path, None, f"[ping360] {key} must be a string, got {values[key]!r}")
    if "nav" in values:
        values["nav"] = tuple(
            str((path.parent / n).resolve()) for n in _nav_names(values["nav"], path)
        )
    for key in ("speed_of_sound_mps", "utc_offset_h"):
        v = values.get(key)
        if key in values and (isinstance(v, bool) or not isinstance(v, (int, float))):
            raise DataError(path, None, f"[ping360] {key} must be a number, got {v!r}")
        if key in values:
            values[key] = float(v)  # type: ignore[arg-type]
    try:
        return replace(base, **values)
    except (SettingError, ValueError) as exc:
        raise DataError(path, None, f"[ping360]: {exc}") from None


def ping360_settings(toml: str | Path, base: Ping360Settings | None = None) -> Ping360Settings:
    """The ``[ping360]`` table of a ``sonarslam.toml`` over ``base`` (default: the defaults),
    checked: an unknown key, a value of the wrong type or out of range is a :class:`DataError`
    naming the file; ``nav`` resolved against the file's folder."""
    p = Path(toml)
    return _settings(_table(p)[0], p, base or Ping360Settings())


def open_ping360(
    path: str | Path,
    config_override: str | Path | None = None,
    topics_file: str | Path | None = None,
    nav: str | Path | Sequence[str | Path] | None = None,
) -> Dataset:
    """A Ping Viewer ``.bin`` log and its navigation as a gated :class:`Dataset`.

    Parameters
    ----------
    path : str or Path
        The ``.bin``; its ``sonarslam.toml`` is the one beside it (module docstring).
    config_override : str or Path, optional
        A ``sonarslam.toml``-format file over it (its ``[ping360]`` keys too).
    topics_file : str or Path, optional
        The navigation bag's roles (``[topics]`` dvl, imu, gps).
    nav : str or Path, or a sequence of them, optional
        The navigation (a ROS bag or a CSV; or a BlueROV2's own logs, one or several:
        :mod:`sonarslam.datasets.navlog`), over ``[ping360] nav``.

    Raises
    ------
    DataError
        Every fault of :func:`read_ping360_log`, :func:`read_nav_csv` and the bag reader,
        naming the file.

    Notes
    -----
    Without any navigation (no ``nav``, no ``[ping360] nav``) the log is read as a still head
    (:attr:`Dataset.still`, :data:`STILL_HEAD`), said by a :class:`DataWarning`.
    """
    p = Path(path)
    beside = p.parent / "sonarslam.toml"
    toml = beside if beside.is_file() else None
    settings = Ping360Settings()
    sonar_keys: dict[str, Any] = {}
    where = p
    head_files: dict[str, Path] = {}  # the file that set the head's n_bins, bin_size_m last
    for source in (toml, Path(config_override) if config_override is not None else None):
        if source is not None:
            table, sonar = _table(source)
            settings = _settings(table, source, settings)
            sonar_keys.update(sonar)
            where = source if table else where
            head_files.update(
                {k: source for k in ("n_bins", "bin_size_m", "step_deg") if k in sonar}
            )
    nav_paths = _nav_paths(nav, settings)
    if toml is not None:
        config, calibration = load_dataset_config(toml), str(toml)
    else:
        config, calibration = DatasetConfig(), NEUTRAL_CALIBRATION
        if config_override is None:
            warnings.warn(neutral_warning(p), DataWarning, stacklevel=3)
    if config_override is not None:
        config = load_dataset_config(config_override, base=config)
        calibration = f"{calibration}; over it {config_override}"
    log = read_ping360_log(p, settings, where)
    n_bins = log.n_bins
    wrong = [
        key
        for key, differs in (
            ("n_bins", config.sonar.n_bins != n_bins),
            ("bin_size_m", not math.isclose(config.sonar.bin_size_m, log.bin_size_m)),
        )
        if key in sonar_keys and differs
    ]
    if wrong:
        head_file = head_files[wrong[-1]]
        raise DataError(
            head_file,
            toml_file_line(head_file, "sonar", (wrong[-1],)),
            f"[sonar] n_bins {config.sonar.n_bins}, bin_size_m {config.sonar.bin_size_m:g}: the"
            f" log's beams have {n_bins} samples of {log.bin_size_m:g} m at"
            f" {settings.speed_of_sound_mps:g} m/s"
            + (" (its farthest-reaching segment)" if len(log.segments) > 1 else "")
            + " (leave them out: the log's win; the speed of sound is [ping360]"
            " speed_of_sound_mps)",
        )
    head = replace(config.sonar, n_bins=n_bins, bin_size_m=log.bin_size_m)
    if log.step_grad > 0:
        own = log.step_grad * math.pi / 200.0
        if "step_deg" not in sonar_keys:
            head = replace(head, step_rad=own)
        elif abs(head.step_rad / own - 1.0) > STEP_TOLERANCE:
            raise DataError(
                head_files["step_deg"],
                toml_file_line(head_files["step_deg"], "sonar", ("step_deg",)),
                f"[sonar] step_deg {math.degrees(head.step_rad):g}: the log's head steps by"
                f" {log.step_grad} gradians ({math.degrees(own):.3g} deg; leave step_deg out,"
                " the log's own is taken)",
            )
    if "beam_width_deg" not in sonar_keys:
        head = replace(head, beam_width_rad=math.radians(PING360_BEAM_WIDTH_DEG))
    config = replace(config, sonar=head)
    beams = log.beams
    if config.sonar_time_offset_s:
        beams = beams.shifted(config.sonar_time_offset_s)
    offset = config.sonar_time_offset_s
    segments = tuple(replace(g, t0_s=g.t0_s + offset, t1_s=g.t1_s + offset) for g in log.segments)
    if not nav_paths:
        if topics_file is not None:
            raise DataError(Path(topics_file), None, "--topics is for a navigation bag: none given")
        return _still_dataset(p, config, calibration, beams, log, segments)
    dvl, att, gps, nav_counts, config, said = _navigation(
        nav_paths, topics_file, config, (toml, config_override)
    )
    calibration = f"{calibration}; {said}" if said else calibration
    _check_clocks(p, beams, dvl, att, settings)
    truth = p.parent / "truth.json"
    d = gated_dataset(
        p.stem,
        p,
        config,
        beams,
        dvl,
        att,
        gps,
        calibration,
        truth=read_truth(truth) if truth.is_file() else None,
        sonar_path=p,
    )
    d.report.counts.update(log.counts)
    d.report.counts.update(nav_counts)
    return replace(d, inputs=(*nav_paths, *_topics_path(topics_file)), segments=segments)


#: What a log without navigation is read as, said by a warning and wherever a run starts.
STILL_HEAD = (
    "no navigation (no --nav, no [ping360] nav): read as a still head at --start X,Y,YAW"
    " (default the origin, heading East: YAW 0); dead reckoning (--backend dr, --poses dr) is"
    " that pose, and the EKF and iSAM2 need a navigation"
)


def _still_dataset(
    p: Path,
    config: DatasetConfig,
    calibration: str,
    beams: BeamSeries,
    log: Ping360Log,
    segments: tuple[SonarSegment, ...],
) -> Dataset:
    """A log without navigation as a still head (:attr:`Dataset.still`): the beams gated
    (their gaps), a DVL and an AHRS of two rows without bottom lock that span them and measure
    nothing."""
    warnings.warn(f"{p}: {STILL_HEAD}", DataWarning, stacklevel=4)
    t0 = float(beams.t_s[0])
    t1 = max(float(beams.t_s[-1]), t0 + 1e-3)
    t = np.array([t0, t1])
    report = SensorReport()
    gate_beams(beams.t_s, config.gates, report, p, (t0, t1))
    report.counts.update(log.counts)
    truth = p.parent / "truth.json"
    return Dataset(
        name=p.stem,
        root=p,
        config=config,
        beams=beams,
        dvl=DvlSeries(t, np.zeros((2, 2)), np.zeros(2, dtype=bool), np.full(2, np.nan)),
        attitude=AttitudeSeries(t.copy(), np.zeros(2), np.zeros(2)),
        gps=None,
        truth=read_truth(truth) if truth.is_file() else None,
        report=report,
        calibration=calibration,
        segments=segments,
        still=True,
    )


def _topics_path(topics_file: str | Path | None) -> tuple[Path, ...]:
    """A ``--topics`` file as an input read (a preset's name is none)."""
    if topics_file is None or str(topics_file) in TOPIC_PRESETS:
        return ()
    return (Path(topics_file),)


def _check_clocks(
    p: Path, beams: BeamSeries, dvl: DvlSeries, att: AttitudeSeries, settings: Ping360Settings
) -> None:
    """Beams that miss the navigation's span by :data:`ZONE_MISS_S` or more, said in one line
    with the likely cause: the file name's clock (local time) when the miss is a time zone
    (within :data:`MAX_ZONE_H`, near a quarter hour), else the navigation's times not being
    Unix seconds (milliseconds, or relative to its start)."""
    t0, t1 = navigation_span_s(dvl, att)
    b0, b1 = float(beams.t_s[0]), float(beams.t_s[-1])
    if not (t0 - b1 >= ZONE_MISS_S or b0 - t1 >= ZONE_MISS_S):
        return
    off_h = (t0 - b0) / 3600.0
    miss = (
        f"the beams ({b0:.3f}-{b1:.3f} s) miss the navigation ({t0:.3f}-{t1:.3f} s) by"
        f" {off_h:+.2f} h"
    )
    quarter = abs(off_h - ZONE_STEP_H * round(off_h / ZONE_STEP_H))
    if abs(off_h) <= MAX_ZONE_H and quarter <= ZONE_SLACK_H:
        raise DataError(
            p,
            None,
            f"{miss}: the log's start comes from its file name, read as UTC"
            f"{settings.utc_offset_h:+g} h (Ping Viewer names it in the computer's local time):"
            " set [ping360] utc_offset_h, or start, in sonarslam.toml",
        )
    nav = dvl.path or att.path
    csv = nav is not None and nav.suffix.lower() == ".csv"
    column = "t_s column is" if csv else "header stamps are"
    if t0 > 100.0 * b1:
        likely = f"milliseconds? (x{t0 / b0:.4g} the beams' times)"
    elif t1 < ZONE_MISS_S * 1000.0:
        likely = (
            "relative to the start? (it starts near 0)"
            if csv
            else "a simulated clock? (a bag recorded with use_sim_time starts near 0): record"
            " with the wall clock, or re-stamp the bag (rosbags can rewrite one)"
        )
    else:
        likely = (
            "another epoch or clock? (or the log's start is wrong: its file name, [ping360] start)"
        )
    raise DataError(
        nav or p,
        None,
        f"{miss}, not a time zone (beyond {MAX_ZONE_H:g} h, or more than"
        f" {ZONE_SLACK_H * 60:g} min off a quarter hour): the navigation's {column} not Unix"
        f" seconds on the sonar's clock: {likely}",
    )


def ping360_table(
    log: str | Path,
    target: str | Path,
    nav: str | Path | Sequence[str | Path] | None = None,
) -> str:
    """The ``[ping360]`` table of a ``.bin``'s ``sonarslam.toml`` as TOML text, for a
    ``sonarslam.toml`` written to ``target`` (``sonarslam calibrate --write``): its ``nav``
    (``nav`` when given: one file or several, as ``--nav`` repeated) relative to ``target``'s
    folder when it lies under it, else absolute, one file as a string, several as a list; ""
    when there is nothing to keep."""
    p = Path(log)
    toml = p.parent / "sonarslam.toml"
    table = dict(_table(toml)[0]) if toml.is_file() else {}
    paths = [toml.parent / n for n in _nav_names(table.pop("nav", ""), toml)]
    if nav is not None:
        paths = [Path(nav)] if isinstance(nav, (str, Path)) else [Path(n) for n in nav]
    folder = Path(target).resolve().parent
    names = []
    for n in (q.resolve() for q in paths):
        names.append(n.relative_to(folder).as_posix() if n.is_relative_to(folder) else str(n))
    if names:
        table = {"nav": names[0] if len(names) == 1 else names, **table}
    if not table:
        return ""
    return "\n" + tomli_w.dumps({"ping360": table})


# -- writing (the simulator's round trip) ---------------------------------------------------------


def _in_digits(text: str, zero: str) -> str:
    """``text`` with its ASCII digits written in the script whose zero is ``zero``
    (``"0"``: as they are; ``"\\u06f0"``: Extended Arabic-Indic, a Persian-locale Windows)."""
    if zero == "0":
        return text
    if not (len(zero) == 1 and zero.isdecimal() and unicodedata.decimal(zero) == 0):
        raise ValueError(f"{zero!r} is not the zero digit of a script")
    return "".join(chr(ord(zero) + int(c)) if c.isascii() and c.isdigit() else c for c in text)


def log_file_name(start_ms: int, zero: str = "0") -> str:
    """Ping Viewer's name of a log started at ``start_ms`` (Unix ms, named in UTC), in the
    digits whose zero is ``zero`` (:func:`ascii_digits` reads any)."""
    when = datetime.fromtimestamp(start_ms // 1000, tz=UTC)
    return _in_digits(f"{when:%Y%m%d-%H%M%S}{start_ms % 1000:03d}", zero) + ".bin"


def _qstring(text: str, encoding: str) -> bytes:
    raw = text.encode(encoding)
    return _U32.pack(len(raw)) + raw


#: Records of a log written as a link delivers its bytes (``write_ping360_log``'s
#: ``split_rng``): each this share of the smallest message at most, so that no record holds
#: the starts of two beams (Ping Viewer's serial link reads a few hundred bytes at a time).
SPLIT_SHARE = 0.6


def write_ping360_log(
    path: str | Path,
    stamps_ms: np.ndarray,
    angles_grad: np.ndarray,
    intensities: np.ndarray,
    sample_period_ticks: int | np.ndarray,
    encoding: str = "utf-16-be",
    transmit_frequency_khz: int = 750,
    gain_settings: np.ndarray | int = 1,
    *,
    n_samples: np.ndarray | None = None,
    split_rng: np.random.Generator | None = None,
    zero: str = "0",
    lose: tuple[int, ...] = (),
) -> Path:
    """Write beams as a Ping Viewer log of ``device_data`` messages (packed by
    ``brping.PingMessage``), a message a record or its bytes split across records as Ping
    Viewer's link delivers them.

    Parameters
    ----------
    path : str or Path
        The ``.bin`` (its name should be :func:`log_file_name` of the start).
    stamps_ms : array of int, shape (N,)
        Each beam's stamp: ms since the log's start (below a day).
    angles_grad : array of int, shape (N,)
        Head angles (gradians, 0-399).
    intensities : array of uint8, shape (N, n)
        The samples, nearest first: a beam's first ``n_samples`` of its row.
    sample_period_ticks : int or array of int, shape (N,)
        25 ns ticks between samples (each beam's: a log whose range changes).
    encoding : str
        The strings' encoding: ``"utf-16-be"`` (``QDataStream``'s) or ``"utf-8"``.
    transmit_frequency_khz : int
    gain_settings : int or array of int, shape (N,)
        Each beam's ``gain_setting`` (0 low, 1 normal, 2 high).
    n_samples : array of int, shape (N,), optional
        Each beam's sample count (200-1200 on a Ping360); default: the rows' width.
    split_rng : numpy.random.Generator, optional
        Write the messages' bytes as one stream cut into records of 1 to
        :data:`SPLIT_SHARE` of the smallest message bytes (uniform), each stamped with the
        stamp of the message its last byte belongs to (a message's first byte is then in a
        record of its own stamp); None: a message a record (the module docstring).
    zero : str
        The zero digit of the stamps' script (``"0"``; ``"\\u06f0"``, Extended Arabic-Indic,
        as a Persian-locale Windows writes them).
    lose : tuple of int
        Beams whose bytes lose their middle third on the way (messages cut short, as a
        serial link that drops bytes delivers them; read back, they are counted, not beams).

    Returns
    -------
    Path
    """
    from brping import PingMessage, definitions  # lazy: only .bin logs load brping

    stamps = np.asarray(stamps_ms, dtype=np.int64)
    grads = np.asarray(angles_grad, dtype=np.int64)
    bins = np.asarray(intensities)
    if (
        bins.dtype != np.uint8
        or bins.ndim != 2
        or not stamps.shape == grads.shape == bins.shape[:1]
    ):
        raise ValueError("stamps (N,), angles (N,) and uint8 intensities (N, n) expected")
    if np.any((grads < 0) | (grads >= GRADIANS_PER_TURN)):
        raise ValueError("angles must be whole gradians 0-399")
    if np.any((stamps < 0) | (stamps >= _DAY_MS)):
        raise ValueError("stamps must be 0 to 24 h (ms)")
    periods = np.broadcast_to(np.asarray(sample_period_ticks, dtype=np.int64), stamps.shape)
    if np.any((periods < 1) | (periods > 0xFFFF)):
        raise ValueError(f"sample periods {sample_period_ticks} ticks are not uint16s")
    gains = np.broadcast_to(np.asarray(gain_settings, dtype=np.int64), stamps.shape)
    if np.any((gains < 0) | (gains > 255)):
        raise ValueError("gain settings must be uint8")
    counts = np.broadcast_to(
        np.asarray(bins.shape[1] if n_samples is None else n_samples, dtype=np.int64),
        stamps.shape,
    )
    if np.any((counts < 1) | (counts > bins.shape[1])):
        raise ValueError(f"n_samples must be 1 to the rows' {bins.shape[1]}")
    messages = []
    for k, (grad, row, gain, period, count) in enumerate(
        zip(grads, bins, gains, periods, counts, strict=True)
    ):
        msg = PingMessage(definitions.PING360_DEVICE_DATA)
        msg.mode = 1
        msg.gain_setting = int(gain)
        msg.angle = int(grad)
        msg.transmit_duration = 10
        msg.sample_period = int(period)
        msg.transmit_frequency = transmit_frequency_khz
        msg.number_of_samples = int(count)
        msg.data_length = int(count)
        msg.data = bytearray(row[:count].tobytes())
        raw = bytes(msg.pack_msg_data())
        if k in lose:
            raw = raw[: len(raw) // 3] + raw[2 * len(raw) // 3 :]
        messages.append(raw)
    p = Path(path)
    with p.open("wb") as fh:
        fh.write(_qstring(LOG_HEADER, encoding) + _I32.pack(LOG_VERSIONS[-1]))
        for text in ("sonarslam", "", "", "", ""):
            fh.write(_qstring(text, encoding))
        fh.write(_I32.pack(1) + _I32.pack(2))  # SensorFamily::PING, PingDeviceType::PING360
        for t_ms, data in _records_of(messages, stamps, split_rng):
            h, rest = divmod(int(t_ms), 3_600_000)
            m, rest = divmod(rest, 60_000)
            s, ms = divmod(rest, 1000)
            fh.write(_qstring(_in_digits(f"{h:02d}:{m:02d}:{s:02d}.{ms:03d}", zero), encoding))
            fh.write(_U32.pack(len(data)) + data)
    return p


def _records_of(
    messages: list[bytes], stamps: np.ndarray, rng: np.random.Generator | None
) -> Iterator[tuple[int, bytes]]:
    """(stamp, bytes) of each record: a message each, or the stream of their bytes cut as
    ``write_ping360_log``'s ``split_rng`` says."""
    if rng is None:
        yield from zip(stamps, messages, strict=True)
        return
    stream = b"".join(messages)
    ends = np.cumsum([len(m) for m in messages])  # each message's end in the stream
    longest = max(int(SPLIT_SHARE * min(len(m) for m in messages)), 1)
    at = 0
    while at < len(stream):
        size = int(rng.integers(1, longest + 1))
        end = min(at + size, len(stream))
        owner = int(np.searchsorted(ends, end - 1, side="right"))  # of the last byte
        yield int(stamps[owner]), stream[at:end]
        at = end
