"""A BlueROV2's own navigation as its autopilot and its ground station log it: QGroundControl
telemetry logs (``.tlog``) and ArduSub dataflash logs (``.bin``), read with pymavlink's
decoders (the ``bluerov`` extra), streamed, surviving the corrupt chunks that real logs carry.

What was read to write this (the code is this project's own):

* pymavlink (ArduPilot/pymavlink at b4c7ca2): ``mavutil.mavlogfile`` (a ``.tlog`` is records of
  an 8-byte big-endian Unix time in microseconds, QGroundControl's receive time, and one MAVLink
  v1 or v2 packet; after a corrupt chunk pymavlink re-reads timestamps byte by byte only when
  the one it reads is more than three days off), ``mavmmaplog.init_arrays`` (the packet
  framing), ``DFReader.DFReader_binary`` (a dataflash log is messages of ``A3 95 type`` and a
  body whose layout an ``FMT`` message gives; its ``init_arrays`` stops at the first unknown
  type after a corrupt chunk, losing the rest of the log, and prints a line per bad byte: why
  the framing here is this module's own, with pymavlink's ``DFFormat`` for the layouts and its
  MAVLink ``decode`` for the packets and their checksums) and ``DFReaderClock_usec``
  (``TimeUS`` to Unix through the first GPS message with a week: GPS time less 18 leap s);
* ArduPilot's ``AP_VisualOdom`` log structure (``VISO``: ``TimeUS, dt, AngDX..Z, PosDX..Z,
  conf``, the deltas in the body frame, forward-right-down);
* BlueOS's Water Linked DVL extension (bluerobotics/BlueOS-Water-Linked-DVL at 6022f84,
  ``dvl-a50/dvl.py`` and ``mavlink2resthelper.py``): it sends each valid A50 velocity report as
  ``VISION_POSITION_DELTA`` with ``position_delta = v * dt`` in the DVL's frame (forward-right-
  down when mounted down), ``time_delta_usec`` the report's ``time`` (ms since the report
  before) times 1000, ``time_usec = 0`` (so the record's time is the only clock), the
  ``angle_delta`` in degrees although MAVLink says radians (not used here), a confidence of
  ``100 (1 - min(fom, 0.4) / 0.4)`` percent, and nothing at all for an invalid report (a gap);
  it also sends the altitude as ``DISTANCE_SENSOR`` (cm, pitch 270: down).

The streams, by what each is taken for:

==============================  ==============================================================
stream                          taken as
==============================  ==============================================================
``VISION_POSITION_DELTA``       odometry (the DVL's own deltas): ``position_delta[0:2] /
(tlog), ``VISO`` (dataflash)    dt``, y negated (forward-right-down to forward-left); a
                                confidence of 0 or a dt of 0 is a row without bottom lock
``LOCAL_POSITION_NED`` (tlog),  the autopilot's velocity estimate (``vx`` North, ``vy`` East):
``XKF1`` core 0 or ``NKF1``     odometry only without the DVL's own
(dataflash); else               (:mod:`sonarslam.datasets.navlog` rotates it into the heading's
``GLOBAL_POSITION_INT``         frame and says so); it is the filter's output, its errors the
                                filter's, not a DVL's
``ATTITUDE`` (tlog), ``ATT``    the heading (a NED ``yaw`` to CCW from East: ``pi/2 - yaw``)
(dataflash)                     and its rate (``-yawspeed``; dataflash: ``-GyrZ`` of ``IMU``
                                0 at the ``ATT`` times)
``GPS_INPUT`` (tlog: a Water    a ruler: positions never fed to an estimate. Underwater it is
Linked Underwater GPS), else    the Underwater GPS's acoustic fix; ArduSub fuses it when
``GPS_RAW_INT``; ``GPS``        ``GPS_TYPE`` is MAVLink, and then its velocity estimate is not
instance 0 (dataflash)          independent of the ruler (:mod:`sonarslam.datasets.navlog`
                                says so when that estimate is the odometry)
``DISTANCE_SENSOR``,            listed (altitude over the bottom, raw rates), not used
``SCALED_IMU2``, ``RAW_IMU``,
``RFND``, ``IMU``
==============================  ==============================================================

Each message type is taken from the source (system, component) that sends most of it; the
others' records are counted (``navlog_other_sources``). Times: a ``.tlog``'s records' receive
times (one clock, the ground station's, which Ping Viewer on the same computer shares); a
dataflash log's ``TimeUS`` put on Unix time by its first GPS message with a week, else by
``[navlog] start``.

Faults: a chunk of bytes that frames no record (a ``.tlog``: a bad marker, a time more than a
minute before the last good one or a day after, a packet of a known id whose checksum fails;
dataflash: no ``A3 95``, a type no ``FMT`` defined, a message whose successor does not start
where its length says) is skipped to the next place where a record frames, checks and is
followed by another that frames, and counted (``navlog_corrupt_chunks``,
``navlog_corrupt_bytes``; one :class:`DataWarning` naming the first's byte offset); a log cut
inside its last record loses it (said); a dataflash log's zero or 0xFF padding after its last
message is not a fault.
"""

from __future__ import annotations

import array
import math
import struct
import warnings
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any, BinaryIO

import numpy as np

from sonarslam.datasets.errors import DataError, DataWarning, MissingExtraError
from sonarslam.datasets.geodesy import geodetic_to_local_en
from sonarslam.datasets.logfile import open_regular
from sonarslam.datasets.navrecords import (
    EARLIEST_UNIX_S,
    LATEST_UNIX_S,
    NavLog,
    NavLogSettings,
    Stream,
    WorldVelocity,
    stream_of,
    unix_s_of_iso,
)
from sonarslam.datasets.records import AttitudeSeries, DvlSeries, GpsSeries

__all__ = [
    "TLOG_KIND",
    "DATAFLASH_KIND",
    "is_tlog",
    "is_dataflash",
    "read_tlog",
    "read_dataflash",
    "mavlink_dialect",
    "dataflash_format",
    "dataflash_formats",
    "gps_time_to_unix_s",
    "GPS_LEAP_S",
    "GPS_EPOCH_UNIX_S",
]

TLOG_KIND = "QGroundControl telemetry log (.tlog)"
DATAFLASH_KIND = "ArduSub dataflash log (.bin)"
_V1, _V2 = 0xFE, 0xFD
_SIGNED = 0x01
_SIGNATURE_BYTES = 13
#: Bytes read at a time: the reader holds about one block and the series, never the file.
BLOCK_BYTES = 1 << 20
#: Longest tlog record: an 8-byte time, a v2 header, 255 payload bytes, CRC and signature.
_MAX_RECORD = 8 + 10 + 255 + 2 + _SIGNATURE_BYTES
#: A record stamped this much earlier than the last good one, or this much later, is not the
#: ground station's next record (s).
_BACK_S = 60.0
_AHEAD_S = 86_400.0
#: Unix seconds at GPS time's zero (6 January 1980) and the leap seconds GPS time
#: has run ahead of UTC since 2017 (pymavlink ``DFReaderClock._gpsTimeToTime``).
GPS_EPOCH_UNIX_S = 315_964_800.0
GPS_LEAP_S = 18.0


def gps_time_to_unix_s(week: float, week_ms: float) -> float:
    """GPS week and milliseconds into the week as Unix s (UTC)."""
    return GPS_EPOCH_UNIX_S + week * 604_800.0 + week_ms * 1e-3 - GPS_LEAP_S


def mavlink_dialect(version: int = 2) -> Any:
    """pymavlink's ArduPilot MAVLink dialect of ``version`` (2, or 1 for the simulator's old
    ground station): its message classes and its ``MAVLink`` codec; a
    :class:`MissingExtraError` naming the ``bluerov`` extra without pymavlink."""
    try:
        if version == 1:
            from pymavlink.dialects.v10 import ardupilotmega as v1  # lazy: only MAVLink logs

            return v1
        from pymavlink.dialects.v20 import ardupilotmega  # lazy: only MAVLink logs need it
    except ModuleNotFoundError as missing:
        raise MissingExtraError("bluerov", "a MAVLink log (.tlog, dataflash)", missing) from None
    return ardupilotmega


def _dflib() -> Any:
    try:
        from pymavlink import DFReader  # lazy: only dataflash logs need it
    except ModuleNotFoundError as missing:
        raise MissingExtraError("bluerov", "an ArduSub dataflash log", missing) from None
    return DFReader


class _Window:
    """A file read forward a block at a time: :meth:`get` returns the bytes at an offset,
    refilling (and dropping what lies before that offset) as needed."""

    def __init__(self, fh: BinaryIO, size: int) -> None:
        self.fh = fh
        self.size = size
        self.base = 0
        self.buf = fh.read(BLOCK_BYTES)

    def get(self, offset: int, n: int) -> bytes:
        """Up to ``n`` bytes from file ``offset`` (fewer only at the file's end); ``offset``
        never before the last one asked."""
        i = offset - self.base
        if i < 0:  # back before the block (a resync's look-ahead): read from there again
            self.fh.seek(offset)
            self.buf, self.base, i = self.fh.read(max(BLOCK_BYTES, n)), offset, 0
        elif i + n > len(self.buf) and self.base + len(self.buf) < self.size:
            self.fh.seek(self.base + len(self.buf))
            self.buf = self.buf[i:] + self.fh.read(max(BLOCK_BYTES, n))
            self.base, i = offset, 0
        return self.buf[i : i + n]


def _head(path: Path, n: int) -> bytes:
    try:
        with open_regular(path) as fh:
            return fh.read(n)
    except DataError:
        return b""


def _time_us(raw: bytes) -> float:
    return int.from_bytes(raw[:8], "big") * 1e-6


def _packet_length(head: bytes, i: int) -> int:
    """Bytes of the MAVLink packet whose marker is ``head[i]`` (its header from there)."""
    if head[i] == _V2:
        return 10 + head[i + 1] + 2 + (_SIGNATURE_BYTES if head[i + 2] & _SIGNED else 0)
    return 6 + head[i + 1] + 2


def _msgid(packet: bytes) -> int:
    if packet[0] == _V2:
        return packet[7] | (packet[8] << 8) | (packet[9] << 16)
    return packet[5]


def _source(packet: bytes) -> tuple[int, int]:
    return (packet[5], packet[6]) if packet[0] == _V2 else (packet[3], packet[4])


def is_tlog(path: str | Path) -> bool:
    """A QGroundControl telemetry log, by content: its first records frame as a Unix time in
    microseconds (2000-2100) and a MAVLink packet (the name is not looked at)."""
    head = _head(Path(path), 3 * _MAX_RECORD)
    i = n = 0
    while i + 11 <= len(head) and n < 3:
        t = _time_us(head[i : i + 8])
        if not EARLIEST_UNIX_S <= t <= LATEST_UNIX_S or head[i + 8] not in (_V1, _V2):
            return False
        i += 8 + _packet_length(head, i + 8)
        n += 1
    return n >= 1


def is_dataflash(path: str | Path) -> bool:
    """An ArduPilot dataflash log, by content: it starts with an ``FMT`` message (``A3 95 80``,
    a type, a length, a name of ASCII letters and digits; ArduPilot's first is ``FMT``'s own);
    a Ping Viewer ``.bin`` starts with the byte count of its header string."""
    head = _head(Path(path), 9)
    name = head[5:9].rstrip(b"\0")
    return head[:3] == b"\xa3\x95\x80" and len(name) > 0 and name.isalnum() and name.isascii()


class _Rows:
    """Rows of one stream, a float array per field (memory: 8 bytes a value)."""

    __slots__ = ("t", "fields")

    def __init__(self, names: tuple[str, ...]) -> None:
        self.t = array.array("d")
        self.fields = {n: array.array("d") for n in names}

    def add(self, t: float, values: tuple[float, ...]) -> None:
        self.t.append(t)
        for column, v in zip(self.fields.values(), values, strict=True):
            column.append(v)

    def __len__(self) -> int:
        return len(self.t)

    def arrays(self, shift_s: float = 0.0) -> tuple[np.ndarray, dict[str, np.ndarray]]:
        """Times (+ ``shift_s``) and fields, sorted by time (stable)."""
        t = np.frombuffer(self.t, dtype=np.float64) + shift_s
        order = np.argsort(t, kind="stable")
        return t[order], {
            n: np.frombuffer(c, dtype=np.float64)[order] for n, c in self.fields.items()
        }


@dataclass
class _Faults:
    """Corrupt chunks met while framing: how many, their bytes, the first's offset."""

    chunks: int = 0
    bytes: int = 0
    first_offset: int = -1
    checksum_errors: int = 0
    cut_tail_bytes: int = 0

    def skipped(self, offset: int, n: int) -> None:
        self.chunks += 1
        self.bytes += n
        if self.first_offset < 0:
            self.first_offset = offset


# -- .tlog ----------------------------------------------------------------------------------

#: The fields kept of each message a ``.tlog`` is read for.
_TLOG_FIELDS: dict[str, tuple[str, ...]] = {
    "ATTITUDE": ("yaw", "yawspeed"),
    "LOCAL_POSITION_NED": ("vx", "vy"),
    "GLOBAL_POSITION_INT": ("vx", "vy"),
    "VISION_POSITION_DELTA": ("time_delta_usec", "dx", "dy", "confidence"),
    "GPS_INPUT": ("lat", "lon", "fix_type"),
    "GPS_RAW_INT": ("lat", "lon", "fix_type"),
}
_TLOG_USE = {
    "ATTITUDE": "heading",
    "VISION_POSITION_DELTA": "odometry (the DVL's own)",
    "LOCAL_POSITION_NED": "the autopilot's velocity",
    "GLOBAL_POSITION_INT": "the autopilot's velocity (without LOCAL_POSITION_NED)",
    "GPS_INPUT": "ruler (Underwater GPS)",
    "GPS_RAW_INT": "ruler (without GPS_INPUT)",
    "DISTANCE_SENSOR": "not read (altitude)",
    "SCALED_IMU2": "not read (ATTITUDE's yawspeed is the rate)",
    "RAW_IMU": "not read (ATTITUDE's yawspeed is the rate)",
}


def _tlog_values(name: str, m: Any) -> tuple[float, ...]:
    if name == "VISION_POSITION_DELTA":
        pd = m.position_delta
        return (float(m.time_delta_usec), float(pd[0]), float(pd[1]), float(m.confidence))
    return tuple(float(getattr(m, f)) for f in _TLOG_FIELDS[name])


def _tlog_frames(w: _Window, offset: int, last_t: float) -> int | None:
    """The packet length of the tlog record at ``offset`` when it frames (a marker, a time
    near the last good one, the whole packet in the file); None when not; -1 when the file
    ends inside it."""
    head = w.get(offset, 11)
    if len(head) < 11:
        return -1 if len(head) < 9 or head[8] in (_V1, _V2) else None
    if head[8] not in (_V1, _V2):
        return None
    t = _time_us(head)
    if not EARLIEST_UNIX_S <= t <= LATEST_UNIX_S:
        return None
    if last_t > -math.inf and not last_t - _BACK_S <= t <= last_t + _AHEAD_S:
        return None
    n = _packet_length(head, 8)
    return -1 if offset + 8 + n > w.size else n


def _decodes(codec: Any, packet: bytes) -> bool:
    """The packet has an id the dialect knows and its checksum holds."""
    try:
        return not codec.decode(bytearray(packet)).get_type().startswith("UNKNOWN")
    except Exception:  # pymavlink's MAVError, struct errors: not a packet
        return False


def _tlog_resync(w: _Window, offset: int, last_t: float, codec: Any) -> int:
    """The next offset from ``offset`` where a record frames, its packet decodes and the record
    after it frames too (or the file ends there); -1 when none."""
    while offset + 9 <= w.size:
        chunk = w.get(offset, 1 << 16)
        for k in range(len(chunk) - 8):
            if chunk[k + 8] not in (_V1, _V2):
                continue
            o = offset + k
            n = _tlog_frames(w, o, last_t)
            if n is None or n < 0:
                continue
            if not _decodes(codec, w.get(o + 8, n)):
                continue
            after = o + 8 + n
            if after >= w.size or _tlog_frames(w, after, last_t) is not None:
                return o
        offset += max(len(chunk) - 8, 1)
    return -1


def _vouched(w: _Window, offset: int, last_t: float, codec: Any) -> bool:
    """The record at ``offset`` (after one of an id the dialect does not know, which no
    checksum can check) frames and decodes, or the file ends there."""
    if offset >= w.size:
        return True
    n = _tlog_frames(w, offset, last_t)
    return n is not None and n > 0 and _decodes(codec, w.get(offset + 8, n))


def _iter_tlog(path: Path, codec: Any, faults: _Faults) -> Iterator[tuple[float, bytes, int]]:
    """``(time s, packet, file offset)`` of each tlog record that frames, in file order; a
    corrupt chunk skipped to the next record that frames and checks (module docstring). A
    record of an id the dialect does not know is taken when the record after it decodes."""
    codec_ids = set(mavlink_dialect().mavlink_map)
    with open_regular(path) as fh:
        size = fh.seek(0, 2)
        fh.seek(0)
        w = _Window(fh, size)
        offset, last_t = 0, -math.inf
        while offset < size:
            n = _tlog_frames(w, offset, last_t)
            if n == -1:
                faults.cut_tail_bytes = size - offset
                return
            record = w.get(offset, 8 + n) if n is not None else b""
            if n is None or (
                _msgid(record[8:]) not in codec_ids
                and not _vouched(w, offset + 8 + n, last_t, codec)
            ):
                found = _tlog_resync(w, offset + 1, last_t, codec)
                faults.skipped(offset, (size if found < 0 else found) - offset)
                if found < 0:
                    return
                offset = found
                continue
            t = _time_us(record)
            yield t, record[8:], offset
            last_t = max(last_t, t)
            offset += 8 + n


def read_tlog(path: str | Path, settings: NavLogSettings | None = None) -> NavLog:
    """Read a QGroundControl ``.tlog`` (module docstring): the streams it holds, the DVL's own
    deltas, the autopilot's velocity, the heading and a GPS ruler, streamed (a block of the
    file and the series in memory).

    Raises
    ------
    DataError
        Naming the file: no record that frames.
    """
    p = Path(path)
    dialect = mavlink_dialect()
    codec = dialect.MAVLink(None)
    names = {k: v.msgname for k, v in dialect.mavlink_map.items()}
    wanted = {k: n for k, n in names.items() if n in _TLOG_FIELDS}
    faults = _Faults()
    times: dict[int, array.array[float]] = {}  # the streams read: every record's time
    seen: dict[int, list[float]] = {}  # the others: count, first and last time
    rows: dict[tuple[str, tuple[int, int]], _Rows] = {}
    for t, packet, offset in _iter_tlog(p, codec, faults):
        msgid = _msgid(packet)
        name = wanted.get(msgid)
        if name is None:
            c = seen.get(msgid)
            if c is None:
                seen[msgid] = [1.0, t, t]
            else:
                c[0] += 1.0
                c[1], c[2] = min(c[1], t), max(c[2], t)
            continue
        times.setdefault(msgid, array.array("d")).append(t)
        try:
            m = codec.decode(bytearray(packet))
        except Exception:  # pymavlink's MAVError: a packet whose checksum fails
            faults.checksum_errors += 1
            if faults.first_offset < 0:
                faults.first_offset = offset
            continue
        key = (name, _source(packet))
        if key not in rows:
            rows[key] = _Rows(_TLOG_FIELDS[name])
        rows[key].add(t, _tlog_values(name, m))
    if not times and not seen:
        raise DataError(p, None, "no MAVLink record frames: not a QGroundControl .tlog")
    counts = _fault_counts(p, faults, "record")
    picked, other = _dominant(rows)
    counts["navlog_other_sources"] = other
    listed = [
        stream_of(names[i], np.frombuffer(ts, dtype=np.float64), _TLOG_USE.get(names[i], ""))
        for i, ts in times.items()
    ]
    for i, (n, first, last) in seen.items():  # not read: no gaps looked for
        rate = (n - 1.0) / (last - first) if last > first else 0.0
        name = names.get(i, f"id {i}")
        listed.append(Stream(name, int(n), first, last, rate, 0, 0.0, _TLOG_USE.get(name, "")))
    streams = tuple(sorted(listed, key=lambda s: s.name))
    return _nav_log(p, TLOG_KIND, streams, picked, counts)


def _dominant(rows: dict[tuple[str, tuple[int, int]], _Rows]) -> tuple[dict[str, _Rows], int]:
    """Each stream's rows from the source that sent most of them; the count of the others'."""
    best: dict[str, _Rows] = {}
    other = 0
    for (name, _), r in sorted(rows.items(), key=lambda kv: -len(kv[1])):
        if name in best:
            other += len(r)
        else:
            best[name] = r
    return best, other


def _fault_counts(p: Path, faults: _Faults, unit: str) -> dict[str, int]:
    if faults.chunks or faults.checksum_errors:
        warnings.warn(
            f"{p}: {faults.chunks} corrupt chunk(s) ({faults.bytes} bytes) skipped to the next"
            f" {unit} that frames, {faults.checksum_errors} {unit}(s) whose checksum or layout"
            f" fails dropped; the first at byte offset {faults.first_offset} (the records in"
            " them are lost: gaps in their streams)",
            DataWarning,
            stacklevel=3,
        )
    if faults.cut_tail_bytes:
        warnings.warn(
            f"{p}: the log ends inside a {unit} (its last {faults.cut_tail_bytes} bytes): dropped",
            DataWarning,
            stacklevel=3,
        )
    return {
        "navlog_corrupt_chunks": faults.chunks,
        "navlog_corrupt_bytes": faults.bytes,
        "navlog_checksum_errors": faults.checksum_errors,
        "navlog_cut_tail_bytes": faults.cut_tail_bytes,
    }


def _nav_log(
    p: Path,
    kind: str,
    streams: tuple[Stream, ...],
    rows: dict[str, _Rows],
    counts: dict[str, int],
    notes: tuple[str, ...] = (),
    shift_s: float = 0.0,
) -> NavLog:
    """The series of a MAVLink log's rows, named as the tlog's streams (a dataflash log's are
    renamed to them by :func:`_df_as_tlog`), their times + ``shift_s``."""
    tlog = kind == TLOG_KIND
    attitude = None
    if "ATTITUDE" in rows:
        t, f = rows["ATTITUDE"].arrays(shift_s)
        yaw = np.angle(np.exp(1j * (0.5 * math.pi - f["yaw"])))  # NED heading to ENU yaw
        attitude = AttitudeSeries(t, yaw, -f["yawspeed"], p)
    dvl = None
    if "VISION_POSITION_DELTA" in rows:
        t, f = rows["VISION_POSITION_DELTA"].arrays(shift_s)
        dt = f["time_delta_usec"] * 1e-6
        ok = (dt > 0) & (f["confidence"] > 0)
        safe = np.where(dt > 0, dt, 1.0)
        v = np.column_stack([f["dx"] / safe, -f["dy"] / safe])  # forward-right to forward-left
        v[~ok] = 0.0
        dvl = DvlSeries(t, v, ok, np.full(t.size, np.nan), p)
    autopilot, autopilot_source = None, ""
    for name in ("LOCAL_POSITION_NED", "GLOBAL_POSITION_INT"):
        if name in rows:
            t, f = rows[name].arrays(shift_s)
            scale = 0.01 if name == "GLOBAL_POSITION_INT" else 1.0  # cm/s
            autopilot = WorldVelocity(t, np.column_stack([f["vy"], f["vx"]]) * scale, p)
            autopilot_source = (
                f"{name} vx, vy (the autopilot's velocity estimate)"
                if tlog
                else "XKF1/NKF1 VN, VE (the autopilot's EKF velocity, core 0)"
            )
            break
    gps, gps_source = None, ""
    for name in ("GPS_INPUT", "GPS_RAW_INT"):
        if name in rows:
            t, f = rows[name].arrays(shift_s)
            lat, lon = f["lat"] * 1e-7, f["lon"] * 1e-7
            fix = (f["fix_type"] >= 2) & ~((lat == 0.0) & (lon == 0.0))
            if not fix.any():
                continue
            i0 = int(np.flatnonzero(fix)[0])
            origin = (float(lat[i0]), float(lon[i0]))
            gps = GpsSeries(t, geodetic_to_local_en(lat, lon, *origin), origin, fix, p)
            gps_source = {
                "GPS_INPUT": "GPS_INPUT (the Water Linked Underwater GPS's acoustic fixes)",
                "GPS_RAW_INT": "GPS_RAW_INT (the autopilot's GPS)" if tlog else "GPS instance 0",
            }[name]
            break
    return NavLog(
        path=p,
        kind=kind,
        streams=streams,
        dvl=dvl,
        dvl_source=(
            "VISION_POSITION_DELTA (the DVL's own deltas as the BlueOS DVL extension sends them,"
            " over their time_delta_usec)"
            if tlog
            else "VISO (the DVL's own deltas the autopilot received, over their dt)"
        )
        if dvl is not None
        else "",
        autopilot=autopilot,
        autopilot_source=autopilot_source,
        attitude=attitude,
        heading_source=(
            "ATTITUDE yaw (the autopilot's AHRS)" if tlog else "ATT Yaw (the autopilot's AHRS)"
        )
        if attitude is not None
        else "",
        heading_absolute=True,
        gps=gps,
        gps_source=gps_source,
        counts=counts,
        notes=notes,
    )


# -- dataflash ----------------------------------------------------------------------------------

_DF_HEAD = b"\xa3\x95"
_FMT_TYPE = 0x80
_FMT_LENGTH = 89
#: The dataflash messages kept and their columns (with ``TimeUS`` first).
_DF_FIELDS: dict[str, tuple[str, ...]] = {
    "ATT": ("Yaw",),
    "IMU": ("I", "GyrZ"),
    "XKF1": ("C", "VN", "VE"),
    "NKF1": ("VN", "VE"),
    "VISO": ("dt", "PosDX", "PosDY", "conf"),
    "GPS": ("I", "Status", "GMS", "GWk", "Lat", "Lng"),
}
_DF_USE = {
    "ATT": "heading",
    "VISO": "odometry (the DVL's own)",
    "XKF1": "the autopilot's velocity (core 0)",
    "NKF1": "the autopilot's velocity",
    "GPS": "ruler (instance 0)",
    "IMU": "the heading's rate (instance 0)",
    "RFND": "not used (altitude)",
}
#: Bytes after a dataflash log's last message that are all 0x00 or 0xFF: a block logger's
#: padding of its last page, not a fault.
_PADDING = frozenset((0x00, 0xFF))


def dataflash_format(type_id: int, name: str, fmt: str, columns: str) -> Any:
    """pymavlink's ``DFFormat`` of a dataflash message (its ``msg_struct``, ``msg_mults``,
    ``colhash``); the length is the format's."""
    df = _dflib()
    length = 3 + struct.calcsize(df.DFFormat(type_id, name, 0, fmt, columns).msg_struct)
    return df.DFFormat(type_id, name, length, fmt, columns)


def dataflash_formats() -> dict[int, Any]:
    """The formats every dataflash log starts with: ``FMT``'s own, as pymavlink's
    ``DFFormat``."""
    df = _dflib()
    return {
        _FMT_TYPE: df.DFFormat(
            _FMT_TYPE, "FMT", _FMT_LENGTH, "BBnNZ", "Type,Length,Name,Format,Columns"
        )
    }


def _df_format(df: Any, body: bytes) -> Any:
    """pymavlink's ``DFFormat`` of an ``FMT`` message's body, or None when it is not one."""
    try:
        ftype, flen, name, fmt, columns = struct.unpack("<BB4s16s64s", body)
        out = df.DFFormat(
            ftype,
            name.split(b"\0")[0].decode("ascii"),
            flen,
            fmt.split(b"\0")[0].decode("ascii"),
            columns.split(b"\0")[0].decode("ascii"),
        )
    except Exception:  # a corrupt FMT: struct, decode or DFFormat's own errors
        return None
    return out if struct.calcsize(out.msg_struct) == flen - 3 else None


def _df_frames(w: _Window, offset: int, formats: dict[int, Any]) -> Any:
    """The format of the dataflash message at ``offset`` when it frames (``A3 95``, a type an
    ``FMT`` defined, the next message starting with ``A3 95`` or padding or the file's end);
    None when not; -1 when the file ends inside it."""
    head = w.get(offset, 3)
    if len(head) < 3:
        return -1
    if head[:2] != _DF_HEAD:
        return None
    fmt = formats.get(head[2])
    if fmt is None:
        return None
    after = offset + fmt.len
    if after > w.size:
        return -1
    nxt = w.get(offset, fmt.len + 2)[fmt.len :]
    if len(nxt) == 2 and nxt != _DF_HEAD and not set(nxt) <= _PADDING:
        return None
    return fmt


def _df_resync(w: _Window, offset: int, formats: dict[int, Any]) -> int:
    while offset + 3 <= w.size:
        chunk = w.get(offset, 1 << 16)
        k = chunk.find(_DF_HEAD)
        while k >= 0:
            o = offset + k
            fmt = _df_frames(w, o, formats)
            if fmt is not None and fmt != -1:
                return o
            chunk = w.get(offset, 1 << 16)
            k = chunk.find(_DF_HEAD, k + 1)
        offset += max(len(chunk) - 1, 1)
    return -1


def _padding_from(w: _Window, offset: int) -> bool:
    """Only 0x00 or 0xFF bytes from ``offset`` to the file's end."""
    while offset < w.size:
        chunk = w.get(offset, 1 << 16)
        if not set(chunk) <= _PADDING:
            return False
        offset += len(chunk)
    return True


def _iter_dataflash(
    path: Path, faults: _Faults, formats: dict[int, Any]
) -> Iterator[tuple[Any, bytes]]:
    """``(format, body)`` of each dataflash message that frames; ``formats`` grows with the
    ``FMT`` messages read."""
    df = _dflib()
    with open_regular(path) as fh:
        size = fh.seek(0, 2)
        fh.seek(0)
        w = _Window(fh, size)
        offset = 0
        while offset < size:
            fmt = _df_frames(w, offset, formats)
            if fmt == -1:
                if not _padding_from(w, offset):
                    faults.cut_tail_bytes = size - offset
                return
            if fmt is None:
                if _padding_from(w, offset):
                    return
                found = _df_resync(w, offset + 1, formats)
                faults.skipped(offset, (size if found < 0 else found) - offset)
                if found < 0:
                    return
                offset = found
                continue
            body = w.get(offset, fmt.len)[3:]
            if fmt.type == _FMT_TYPE:
                new = _df_format(df, body)
                if new is not None:
                    formats[new.type] = new
            yield fmt, body
            offset += fmt.len


def read_dataflash(path: str | Path, settings: NavLogSettings | None = None) -> NavLog:
    """Read an ArduSub dataflash ``.bin`` (module docstring), streamed.

    Raises
    ------
    DataError
        Naming the file: no message that frames; no clock (no GPS message with a week, and no
        ``[navlog] start``).
    """
    p = Path(path)
    settings = settings or NavLogSettings()
    faults = _Faults()
    formats = dataflash_formats()
    times: dict[str, array.array[float]] = {}
    rows: dict[str, _Rows] = {}
    layouts: dict[int, tuple[struct.Struct, list[int], list[float]]] = {}
    gps_clock: float | None = None
    version = ""
    for fmt, body in _iter_dataflash(p, faults, formats):
        if fmt.type == _FMT_TYPE:
            continue
        name = fmt.name
        if fmt.type not in layouts:
            columns = ("TimeUS", *_DF_FIELDS.get(name, ()))
            idx = [fmt.colhash[c] for c in columns if c in fmt.colhash]
            if len(idx) != len(columns) and name in _DF_FIELDS:
                idx = idx[:1]  # another firmware's layout: listed, not read
            if "TimeUS" not in fmt.colhash:
                idx = []
            mults = [fmt.msg_mults[i] or 1.0 for i in idx]
            layouts[fmt.type] = (struct.Struct(fmt.msg_struct), idx, mults)
        unpack, idx, mults = layouts[fmt.type]
        try:
            values = unpack.unpack(body)
        except struct.error:
            faults.checksum_errors += 1
            continue
        if name == "MSG" and not version and isinstance(values[-1], bytes):
            version = values[-1].split(b"\0")[0].decode("ascii", "replace")
        if not idx:
            continue
        t = float(values[idx[0]]) * 1e-6
        times.setdefault(name, array.array("d")).append(t)
        if name not in _DF_FIELDS or len(idx) == 1:
            continue
        row = tuple(float(values[i]) * m for i, m in zip(idx[1:], mults[1:], strict=True))
        if name not in rows:
            rows[name] = _Rows(_DF_FIELDS[name])
        rows[name].add(t, row)
        if name == "GPS" and gps_clock is None and row[3] > 0:
            gps_clock = gps_time_to_unix_s(row[3], row[2]) - t
    if not times:
        raise DataError(p, None, "no dataflash message frames: not an ArduPilot dataflash log")
    counts = _fault_counts(p, faults, "message")
    notes = []
    if gps_clock is not None:
        clock = gps_clock
        notes.append(
            "clock: TimeUS (from the autopilot's boot) on GPS time by its first GPS message with"
            " a week, less 18 leap s"
        )
    elif settings.start:
        first = min(float(np.min(np.frombuffer(a, dtype=np.float64))) for a in times.values())
        clock = unix_s_of_iso(settings.start, settings.utc_offset_h, p, "[navlog] start") - first
        notes.append("clock: TimeUS (from the autopilot's boot) put on [navlog] start")
    else:
        raise DataError(
            p,
            None,
            "no GPS time in the log (no GPS message with a week): its TimeUS counts from the"
            " autopilot's boot; give the date and time of its first message as [navlog] start ="
            ' "2024-05-02T10:31:07.250+02:00" in the sonarslam.toml beside it',
        )
    if version:
        notes.append(f"firmware: {version}")
    streams = tuple(
        stream_of(name, np.frombuffer(ts, dtype=np.float64) + clock, _DF_USE.get(name, ""))
        for name, ts in sorted(times.items())
    )
    return _nav_log(p, DATAFLASH_KIND, streams, _df_as_tlog(rows), counts, tuple(notes), clock)


def _df_as_tlog(rows: dict[str, _Rows]) -> dict[str, _Rows]:
    """A dataflash log's rows as the tlog's streams: ``ATT`` (degrees) with ``IMU`` 0's
    ``GyrZ`` at its times as ``ATTITUDE`` (rad), ``XKF1`` core 0 (else ``NKF1``) as
    ``LOCAL_POSITION_NED``, ``VISO`` as ``VISION_POSITION_DELTA`` (dt in us), ``GPS`` 0 as
    ``GPS_RAW_INT`` (degE7)."""
    out: dict[str, _Rows] = {}

    def rows_of(names: tuple[str, ...], t: np.ndarray, *columns: np.ndarray) -> _Rows:
        r = _Rows(names)
        r.t = array.array("d", np.asarray(t, dtype=np.float64).tobytes())
        r.fields = {
            n: array.array("d", np.asarray(c, dtype=np.float64).tobytes())
            for n, c in zip(names, columns, strict=True)
        }
        return r

    if "ATT" in rows:
        t, f = rows["ATT"].arrays()
        rate = np.zeros(t.size)
        if "IMU" in rows:
            ti, fi = rows["IMU"].arrays()
            first = fi["I"] == 0
            if first.sum() >= 2:
                rate = np.interp(t, ti[first], fi["GyrZ"][first])
        out["ATTITUDE"] = rows_of(("yaw", "yawspeed"), t, np.radians(f["Yaw"]), rate)
    for name in ("XKF1", "NKF1"):
        if name in rows:
            t, f = rows[name].arrays()
            core = f["C"] == 0 if "C" in f else np.ones(t.size, dtype=bool)
            out["LOCAL_POSITION_NED"] = rows_of(("vx", "vy"), t[core], f["VN"][core], f["VE"][core])
            break
    if "VISO" in rows:
        t, f = rows["VISO"].arrays()
        out["VISION_POSITION_DELTA"] = rows_of(
            _TLOG_FIELDS["VISION_POSITION_DELTA"],
            t,
            f["dt"] * 1e6,
            f["PosDX"],
            f["PosDY"],
            f["conf"],
        )
    if "GPS" in rows:
        t, f = rows["GPS"].arrays()
        first = f["I"] == 0
        out["GPS_RAW_INT"] = rows_of(
            ("lat", "lon", "fix_type"),
            t[first],
            f["Lat"][first] * 1e7,  # format L: read in degrees
            f["Lng"][first] * 1e7,
            f["Status"][first],
        )
    return out
