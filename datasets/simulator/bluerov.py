"""A simulated run as a BlueROV2 logs it: the beams as Ping Viewer's ``.bin``
(:mod:`sonarslam.datasets.simulator.ping360`), the navigation as the vehicle's own logs, each
with the defects its writer is known for (module docstrings of the readers name them):

======================  ========================================================================
``nav``                 written
======================  ========================================================================
``tlog``                ``dive.tlog``: QGroundControl's records (receive time +5-20 ms, MAVLink
                        2; a v1 ``HEARTBEAT`` of an old ground station too): ``ATTITUDE``
                        (the AHRS), ``VISION_POSITION_DELTA`` as the BlueOS DVL extension sends
                        it (the valid DVL rows only, ``time_usec`` 0, ``angle_delta`` in
                        degrees), the autopilot's ``LOCAL_POSITION_NED`` and
                        ``GLOBAL_POSITION_INT`` at 10 Hz (:func:`autopilot_velocity`),
                        ``GPS_INPUT`` of an Underwater GPS (the GPS rows), ``DISTANCE_SENSOR``,
                        ``SCALED_IMU2``, a camera's ``ATTITUDE`` at 1 Hz (another source), and
                        corrupt chunks (bytes overwritten, garbage inserted)
``dataflash``           ``00000042.BIN``: ``FMT`` then ``ATT`` (centidegrees), ``IMU``,
                        ``XKF1`` (cores 0 and 1), ``VISO``, ``GPS`` (week and ms), ``MSG``,
                        corrupt chunks, a block logger's zero padding at the end
``dvl_json``            ``dvl.json``: the A50's ``json_v3`` reports (velocity with
                        ``time_of_validity``, ``position_local`` with its relative yaw) and a
                        corrupt line
``dvl_json_v1``         ``dvl.json`` in ``json_v1`` (velocities only, ``time`` ms since the
                        report before; a line lost) with ``[navlog] start``, beside an
                        ``attitude.tlog`` of ``ATTITUDE`` only (json_v1 has no heading)
``qgc_csv``             ``2024-05-02 10-31-07 vehicle1.csv``: QGroundControl's CSV export (1 Hz,
                        local time, display decimals) with ``[navlog] utc_offset_h``
======================  ========================================================================

The DVL's velocities are the simulated DVL's (its frame, x forward, y left: the writers turn
them into the forward-right-down frames of MAVLink and the A50); the heading is the simulated
AHRS's; the ruler is the simulated GPS. ``sonarslam.toml`` keeps the scenario's calibration, and
its ``[ping360] nav`` names the first navigation file.
"""

from __future__ import annotations

import json
import math
import struct
import warnings
from datetime import UTC, datetime, timedelta, timezone
from pathlib import Path
from typing import Any

import numpy as np

from sonarslam.datasets.config import dump_dataset_config
from sonarslam.datasets.dataset import Dataset
from sonarslam.datasets.errors import DataWarning
from sonarslam.datasets.geodesy import local_en_to_geodetic
from sonarslam.datasets.mavlink import (
    GPS_EPOCH_UNIX_S,
    GPS_LEAP_S,
    dataflash_format,
    dataflash_formats,
    mavlink_dialect,
)
from sonarslam.datasets.qgccsv import QGC_GPS_LOCKS
from sonarslam.datasets.simulator.ping360 import simulate_ping360
from sonarslam.datasets.source import open_dataset
from sonarslam.features.geometry import FloatArray

__all__ = [
    "NAV_KINDS",
    "autopilot_velocity",
    "write_tlog",
    "write_busy_tlog",
    "write_dataflash",
    "write_dvl_json",
    "write_qgc_csv",
    "write_bluerov_nav",
    "simulate_bluerov",
]

NAV_KINDS = ("tlog", "dataflash", "dvl_json", "dvl_json_v1", "qgc_csv")
#: The simulated autopilot's velocity estimate: its rate (Hz) and its filter's time constant (s).
AUTOPILOT_RATE_HZ = 10.0
AUTOPILOT_TAU_S = 0.5
#: A simulated DVL at this altitude (m): ``DISTANCE_SENSOR``, the A50's ``altitude``.
ALTITUDE_M = 2.0


def _heading_at(d: Dataset, t: FloatArray) -> FloatArray:
    """The AHRS yaw (CCW from East, unwrapped) interpolated at ``t``."""
    return np.interp(t, d.attitude.t, np.unwrap(d.attitude.yaw_rad))


def autopilot_velocity(
    d: Dataset, rate_hz: float = AUTOPILOT_RATE_HZ, tau_s: float = AUTOPILOT_TAU_S
) -> tuple[FloatArray, FloatArray]:
    """A simulated autopilot's velocity estimate: the DVL's valid rows turned into East-North
    by the mountings and the AHRS heading, held between them and smoothed by a first-order
    filter of ``tau_s``, at ``rate_hz``. Returns ``(t (N,), v_en (N, 2))``."""
    ok = d.dvl.valid
    t_dvl = d.dvl.t[ok]
    body_yaw = _heading_at(d, t_dvl) - d.config.ahrs_mounting.yaw_rad
    a = body_yaw + d.config.dvl_mounting.yaw_rad
    vx, vy = d.dvl.v_mps[ok, 0], d.dvl.v_mps[ok, 1]
    v_en = np.column_stack([np.cos(a) * vx - np.sin(a) * vy, np.sin(a) * vx + np.cos(a) * vy])
    t0, t1 = max(d.dvl.t[0], d.attitude.t[0]), min(d.dvl.t[-1], d.attitude.t[-1])
    t = np.arange(t0, t1, 1.0 / rate_hz)
    held = v_en[np.clip(np.searchsorted(t_dvl, t, side="right") - 1, 0, len(t_dvl) - 1)]
    out = np.empty_like(held)
    gain = 1.0 - math.exp(-1.0 / (rate_hz * tau_s))
    y = held[0].copy()
    for k in range(t.size):
        y += gain * (held[k] - y)
        out[k] = y
    return t, out


def _lat_lon(d: Dataset) -> tuple[FloatArray, FloatArray, FloatArray] | None:
    if d.gps is None:
        return None
    lat, lon = local_en_to_geodetic(d.gps.en_m[:, 0], d.gps.en_m[:, 1], *d.gps.origin_lat_lon_deg)
    return d.gps.t, lat, lon


def _ned_yaw(yaw_enu: FloatArray) -> FloatArray:
    """A yaw CCW from East as MAVLink's NED yaw (clockwise from North), in [-pi, pi)."""
    return np.mod(0.5 * math.pi - yaw_enu + math.pi, 2.0 * math.pi) - math.pi


def _corrupt(data: bytearray, rng: np.random.Generator, chunks: int) -> bytearray:
    """``chunks`` corrupt chunks in ``data``, spread over its middle: the odd ones bytes
    overwritten (30-300), the even ones garbage inserted (50-200 bytes)."""
    n = len(data)
    out = bytearray(data)
    spots = sorted(rng.uniform(0.1, 0.9, chunks) * n)
    for k, at in enumerate(reversed(spots)):
        i = int(at)
        if k % 2 == 0:
            m = int(rng.integers(30, 300))
            out[i : i + m] = rng.integers(0, 256, m, dtype=np.uint8).tobytes()
        else:
            m = int(rng.integers(50, 200))
            out[i:i] = rng.integers(0, 256, m, dtype=np.uint8).tobytes()
    return out


#: A BlueROV2's telemetry as QGroundControl logs it, records a second by stream: the reader's
#: streams and the many it only counts (:func:`write_busy_tlog`).
BUSY_RATES_HZ = {"att": 20, "lpn": 10, "vpd": 5, "imu": 10, "hb": 1, "servo": 94}


def write_busy_tlog(
    path: str | Path, span_s: float, corrupt_chunks: int = 0, seed: int = 0
) -> Path:
    """A ``.tlog`` of ``span_s`` at :data:`BUSY_RATES_HZ` (``ATTITUDE``, ``LOCAL_POSITION_NED``,
    ``VISION_POSITION_DELTA``, ``SCALED_IMU2``, ``HEARTBEAT``, ``SERVO_OUTPUT_RAW``), the
    payloads repeated, each record's stamp its own, ``corrupt_chunks`` of 200 bytes overwritten:
    a file to measure the reading's speed and memory by."""
    dialect = mavlink_dialect()
    mav = dialect.MAVLink(None, srcSystem=1, srcComponent=1)
    packets = {
        "att": dialect.MAVLink_attitude_message(1, 0.0, 0.0, 0.5, 0.0, 0.0, 0.01),
        "lpn": dialect.MAVLink_local_position_ned_message(1, 0, 0, 0, 0.2, 0.1, 0),
        "vpd": dialect.MAVLink_vision_position_delta_message(
            0, 200000, [0, 0, 0], [0.04, 0.0, 0.0], 90.0
        ),
        "imu": dialect.MAVLink_scaled_imu2_message(1, 0, 0, -1000, 0, 0, 0, 0, 0, 0),
        "hb": dialect.MAVLink_heartbeat_message(12, 3, 209, 19, 4, 3),
        "servo": dialect.MAVLink_servo_output_raw_message(1, 0, *([1500] * 8)),
    }
    records: list[tuple[float, bytes]] = []
    for name, rate in BUSY_RATES_HZ.items():
        packet = bytes(packets[name].pack(mav))
        for t in 1_700_000_000.0 + np.arange(0.0, span_s, 1.0 / rate):
            records.append((float(t), int(t * 1e6).to_bytes(8, "big") + packet))
    records.sort(key=lambda r: r[0])
    data = bytearray(b"".join(r for _, r in records))
    rng = np.random.default_rng(seed)
    for at in rng.uniform(0.1, 0.9, corrupt_chunks) * len(data):
        data[int(at) : int(at) + 200] = rng.integers(0, 256, 200, dtype=np.uint8).tobytes()
    p = Path(path)
    p.write_bytes(bytes(data))
    return p


def write_tlog(
    d: Dataset,
    path: str | Path,
    rng: np.random.Generator,
    corrupt_chunks: int = 4,
    attitude_only: bool = False,
) -> Path:
    """Write the navigation of ``d`` as a QGroundControl ``.tlog`` (module docstring);
    ``attitude_only``: ``HEARTBEAT`` and ``ATTITUDE`` only."""
    dialect = mavlink_dialect()
    pilot = dialect.MAVLink(None, srcSystem=1, srcComponent=1)
    companion = dialect.MAVLink(None, srcSystem=1, srcComponent=197)
    camera = dialect.MAVLink(None, srcSystem=1, srcComponent=100)
    items: list[tuple[float, bytes]] = []
    boot = float(min(d.attitude.t[0], d.dvl.t[0])) - 30.0

    def ms(t: float) -> int:
        return int(round((t - boot) * 1000.0))

    def put(t: float, msg: Any, src: Any) -> None:
        items.append((t, bytes(msg.pack(src))))

    t_end = float(max(d.attitude.t[-1], d.dvl.t[-1]))
    for t in np.arange(boot + 30.0, t_end, 1.0):
        put(t, dialect.MAVLink_heartbeat_message(12, 3, 209, 19, 4, 3), pilot)
    yaw = _ned_yaw(d.attitude.yaw_rad)
    for t, y, r in zip(d.attitude.t, yaw, d.attitude.yaw_rate_rad_per_s, strict=True):
        put(t, dialect.MAVLink_attitude_message(ms(t), 0.01, -0.02, y, 0.0, 0.0, -r), pilot)
    if not attitude_only:
        for t in d.attitude.t[::10]:  # a camera gimbal's attitude: another source
            put(
                t + 0.003,
                dialect.MAVLink_attitude_message(ms(t), 0.0, 0.0, 1.0, 0.0, 0.0, 0.0),
                camera,
            )
        prev = None
        for t, v, ok in zip(d.dvl.t, d.dvl.v_mps, d.dvl.valid, strict=True):
            dt = (t - prev) if prev is not None else 1.0 / 1.5
            prev = t
            if not ok:
                continue  # BlueOS sends no delta for an invalid report
            pd = [float(v[0] * dt), float(-v[1] * dt), 0.0]
            msg = dialect.MAVLink_vision_position_delta_message(
                0, int(round(dt * 1e6)), [0.1, -0.2, 1.5], pd, 87.5
            )
            put(t, msg, companion)
            dist = int(ALTITUDE_M * 100)
            put(
                t,
                dialect.MAVLink_distance_sensor_message(ms(t), 5, 5000, dist, 0, 0, 25, 0),
                companion,
            )
        t_ap, v_en = autopilot_velocity(d)
        lat_lon = _lat_lon(d)
        for t, v in zip(t_ap, v_en, strict=True):
            put(
                t,
                dialect.MAVLink_local_position_ned_message(ms(t), 0.0, 0.0, 2.0, v[1], v[0], 0.0),
                pilot,
            )
            put(
                t + 0.001,
                dialect.MAVLink_global_position_int_message(
                    ms(t), 0, 0, -2000, -2000, int(round(v[1] * 100)), int(round(v[0] * 100)), 0, 0
                ),
                pilot,
            )
            put(
                t + 0.002,
                dialect.MAVLink_scaled_imu2_message(ms(t), 0, 0, -1000, 0, 0, 0, 0, 0, 0),
                pilot,
            )
        if lat_lon is not None:
            for t, la, lo in zip(*lat_lon, strict=True):
                gps_s = t + GPS_LEAP_S - GPS_EPOCH_UNIX_S
                week = int(gps_s // 604_800)
                msg = dialect.MAVLink_gps_input_message(
                    int(t * 1e6), 0, 0, int(round((gps_s - week * 604_800) * 1000)), week, 3,
                    int(round(la * 1e7)), int(round(lo * 1e7)), -2.0, 1.0, 1.0, 0.0, 0.0, 0.0,
                    0.0, 0.5, 1.0, 10,
                )  # fmt: skip
                put(t, msg, companion)
    items.append((float(d.attitude.t[0]) + 0.5, _v1_heartbeat()))
    latency = rng.uniform(0.005, 0.02, len(items))
    records = sorted((t + lat, packet) for (t, packet), lat in zip(items, latency, strict=True))
    out = bytearray()
    for t, packet in records:
        out += struct.pack(">Q", int(round(t * 1e6))) + packet
    p = Path(path)
    p.write_bytes(bytes(_corrupt(out, rng, corrupt_chunks)))
    return p


def _v1_heartbeat() -> bytes:
    """A MAVLink 1 ``HEARTBEAT`` of an old ground station (system 255)."""
    v10 = mavlink_dialect(version=1)
    return bytes(v10.MAVLink_heartbeat_message(6, 8, 0, 0, 0, 3).pack(v10.MAVLink(None, 255, 190)))


#: The dataflash messages written: name, type id, format, columns.
_DF_MESSAGES = (
    ("ATT", 0x81, "QccccCCCCB", "TimeUS,DesRoll,Roll,DesPitch,Pitch,DesYaw,Yaw,ErrRP,ErrYaw,AEKF"),
    (
        "IMU",
        0x82,
        "QBffffffIIfBBHH",
        "TimeUS,I,GyrX,GyrY,GyrZ,AccX,AccY,AccZ,EG,EA,T,GH,AH,GHz,AHz",
    ),
    ("XKF1", 0x83, "QBccCfffffffccce", "TimeUS,C,Roll,Pitch,Yaw,VN,VE,VD,dPD,PN,PE,PD,GX,GY,GZ,OH"),
    ("VISO", 0x84, "Qffffffff", "TimeUS,dt,AngDX,AngDY,AngDZ,PosDX,PosDY,PosDZ,conf"),
    (
        "GPS",
        0x85,
        "QBBIHBcLLeffffB",
        "TimeUS,I,Status,GMS,GWk,NSats,HDop,Lat,Lng,Alt,Spd,GCrs,VZ,Yaw,U",
    ),
    ("MSG", 0x86, "QZ", "TimeUS,Message"),
    ("RFND", 0x87, "QBCBB", "TimeUS,Instance,Dist,Stat,Orient"),
)


def write_dataflash(
    d: Dataset, path: str | Path, rng: np.random.Generator, corrupt_chunks: int = 3
) -> Path:
    """Write the navigation of ``d`` as an ArduSub dataflash log (module docstring)."""
    fmt_of = dataflash_formats()[0x80]
    out = bytearray(
        b"\xa3\x95\x80"
        + struct.pack(
            fmt_of.msg_struct,
            0x80,
            fmt_of.len,
            b"FMT",
            b"BBnNZ",
            b"Type,Length,Name,Format,Columns",
        )
    )
    layouts = {}
    for name, kind, fmt, cols in _DF_MESSAGES:
        f = dataflash_format(kind, name, fmt, cols)
        length = 3 + struct.calcsize(f.msg_struct)
        layouts[name] = (kind, struct.Struct(f.msg_struct), f.msg_mults)
        body = struct.pack(
            fmt_of.msg_struct, kind, length, name.encode(), fmt.encode(), cols.encode()
        )
        out += b"\xa3\x95\x80" + body
    boot = float(min(d.attitude.t[0], d.dvl.t[0])) - 20.0
    items: list[tuple[float, str, tuple[Any, ...]]] = []

    def us(t: float) -> int:
        return int(round((t - boot) * 1e6))

    items.append((boot + 1.0, "MSG", (us(boot + 1.0), b"ArduSub V4.1.2 (a8a8ee7e)")))
    compass = np.mod(90.0 - np.degrees(d.attitude.yaw_rad), 360.0)
    for t, c, r in zip(d.attitude.t, compass, d.attitude.yaw_rate_rad_per_s, strict=True):
        items.append((t, "ATT", (us(t), 0.0, 0.5, 0.0, -1.0, c, c, 0.1, 0.2, 1)))
        items.append(
            (t, "IMU", (us(t), 0, 0.0, 0.0, -r, 0.0, 0.0, -9.8, 0, 0, 20.0, 1, 1, 400, 400))
        )
        items.append(
            (t, "IMU", (us(t), 1, 0.0, 0.0, 0.3, 0.0, 0.0, -9.8, 0, 0, 20.0, 1, 1, 400, 400))
        )
    prev = None
    for t, v, ok in zip(d.dvl.t, d.dvl.v_mps, d.dvl.valid, strict=True):
        dt = (t - prev) if prev is not None else 1.0 / 1.5
        prev = t
        if ok:
            items.append((t, "VISO", (us(t), dt, 0.0, 0.0, 0.0, v[0] * dt, -v[1] * dt, 0.0, 87.5)))
            items.append((t, "RFND", (us(t), 0, ALTITUDE_M, 4, 25)))
    t_ap, v_en = autopilot_velocity(d)
    for t, v in zip(t_ap, v_en, strict=True):
        for core, bias in ((0, 0.0), (1, 0.3)):
            items.append(
                (t, "XKF1", (us(t), core, 0.0, 0.0, 0.0, v[1] + bias, v[0], 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0))
            )  # fmt: skip
    lat_lon = _lat_lon(d)
    if lat_lon is not None:
        for t, la, lo in zip(*lat_lon, strict=True):
            gps_s = t + GPS_LEAP_S - GPS_EPOCH_UNIX_S
            week = int(gps_s // 604_800)
            week_ms = int(round((gps_s - week * 604_800) * 1000))
            items.append(
                (
                    t,
                    "GPS",
                    (us(t), 0, 3, week_ms, week, 10, 1.0, la, lo, -2.0, 0.0, 0.0, 0.0, 0.0, 1),
                )
            )
    items.sort(key=lambda item: item[0])
    for _, name, values in items:
        kind, layout, mults = layouts[name]
        raw = [
            (round(v / m) if m is not None and not isinstance(v, bytes) else v)
            for v, m in zip(values, mults, strict=True)
        ]
        out += bytes((0xA3, 0x95, kind)) + layout.pack(*raw)
    out = _corrupt(out, rng, corrupt_chunks)
    out += bytes(200)  # a block logger's padding of its last page
    p = Path(path)
    p.write_bytes(bytes(out))
    return p


def _unix_iso(t: float) -> str:
    return datetime.fromtimestamp(t, tz=UTC).isoformat(timespec="milliseconds")


def write_dvl_json(
    d: Dataset,
    path: str | Path,
    rng: np.random.Generator,
    protocol: str = "json_v3",
    bad_lines: int = 1,
) -> Path:
    """Write the DVL of ``d`` as the A50's JSON reports of ``protocol`` (``json_v1``,
    ``json_v2``, ``json_v3``): velocity reports in the A50's frame (x forward, y right), and
    for v2 and later ``position_local`` reports with the AHRS heading made relative (the A50's
    gyro, clockwise, from 0 at the first report); ``bad_lines`` lines cut in the middle."""
    lines: list[tuple[float, str]] = []
    prev = None
    for t, v, ok in zip(d.dvl.t, d.dvl.v_mps, d.dvl.valid, strict=True):
        dt_ms = (t - prev) * 1000.0 if prev is not None else 666.7
        prev = t
        report: dict[str, Any] = {
            "time": round(float(dt_ms), 3),
            "vx": float(v[0]) if ok else 0.0,
            "vy": float(-v[1]) if ok else 0.0,
            "vz": 0.0,
            "fom": 0.002 if ok else 9.0,
            "altitude": ALTITUDE_M if ok else -1.0,
            "transducers": [
                {
                    "id": k,
                    "velocity": 0.0,
                    "distance": ALTITUDE_M,
                    "rssi": -40.0,
                    "nsd": -90.0,
                    "beam_valid": bool(ok),
                }
                for k in range(4)
            ],  # fmt: skip
            "velocity_valid": bool(ok),
            "status": 0,
            "format": protocol,
        }
        if protocol != "json_v1":
            report["type"] = "velocity"
        if protocol == "json_v3":
            report["covariance"] = [[4e-6, 0.0, 0.0], [0.0, 4e-6, 0.0], [0.0, 0.0, 4e-6]]
            report["time_of_validity"] = int(round(t * 1e6))
            report["time_of_transmission"] = int(round((t + 0.12) * 1e6))
        lines.append((float(t), json.dumps(report)))
    if protocol != "json_v1":
        yaw = np.unwrap(d.attitude.yaw_rad)
        rel = -np.degrees(yaw - yaw[0])
        rel = np.mod(rel + 180.0, 360.0) - 180.0
        for t, y in zip(d.attitude.t[::2], rel[::2], strict=True):
            report = {
                "ts": round(float(t), 3), "x": 0.0, "y": 0.0, "z": 0.0, "std": 0.1,
                "roll": 0.0, "pitch": 0.0, "yaw": round(float(y), 4),
                "type": "position_local", "status": 0, "format": protocol,
            }  # fmt: skip
            lines.append((float(t) + 1e-4, json.dumps(report)))
    lines.sort(key=lambda item: item[0])
    text = [line for _, line in lines]
    for k in rng.choice(np.arange(5, len(text) - 5), bad_lines, replace=False):
        text[int(k)] = text[int(k)][: len(text[int(k)]) // 2]  # a corrupt (cut) line
    p = Path(path)
    p.write_text("\n".join(text) + "\n", encoding="utf-8")
    return p


#: QGroundControl's CSV columns written (the vehicle's facts, then its groups').
_QGC_COLUMNS = (
    "roll,pitch,heading,rollRate,pitchRate,yawRate,groundSpeed,airSpeed,climbRate,"
    "altitudeRelative,altitudeAMSL,flightDistance,distanceToHome,missionItemIndex,"
    "headingToNextWP,headingToHome,distanceToGCS,hobbs,throttlePct,"
    "gps.lat,gps.lon,gps.mgrs,gps.hdop,gps.vdop,gps.courseOverGround,gps.lock,gps.count,"
    "localPosition.x,localPosition.y,localPosition.z,localPosition.vx,localPosition.vy,"
    "localPosition.vz"
).split(",")


def write_qgc_csv(d: Dataset, path: str | Path, utc_offset_h: float = 2.0) -> Path:
    """Write the navigation of ``d`` as QGroundControl's CSV export (module docstring): a row
    a second, local time (UTC + ``utc_offset_h``), QGroundControl's display decimals."""
    zone = timezone(timedelta(hours=utc_offset_h))
    t_ap, v_en = autopilot_velocity(d)
    t0, t1 = float(t_ap[0]), float(t_ap[-1])
    rows = [",".join(["Timestamp", *_QGC_COLUMNS])]
    lat_lon = _lat_lon(d)
    for t in np.arange(math.ceil(t0), t1, 1.0):
        yaw = float(_heading_at(d, np.array([t]))[0])
        heading = math.degrees(0.5 * math.pi - yaw) % 360.0
        rate = float(np.interp(t, d.attitude.t, d.attitude.yaw_rate_rad_per_s))
        k = min(int(np.searchsorted(t_ap, t)), t_ap.size - 1)
        ve, vn = v_en[k]
        values = dict.fromkeys(_QGC_COLUMNS, "nan")
        values.update(
            roll="0.0", pitch="0.0", heading=f"{heading:.0f}", yawRate=f"{-math.degrees(rate):.1f}",
            groundSpeed=f"{math.hypot(ve, vn):.1f}", hobbs="0000:00:00", throttlePct="0",
            missionItemIndex="0", **{"gps.mgrs": "", "gps.count": "0", "gps.lock": "None",
            "localPosition.vx": f"{vn:.1f}", "localPosition.vy": f"{ve:.1f}",
            "localPosition.vz": "0.0"},
        )  # fmt: skip
        if lat_lon is not None:
            j = int(np.argmin(np.abs(lat_lon[0] - t)))
            if abs(lat_lon[0][j] - t) < 1.0:
                values["gps.lat"] = f"{lat_lon[1][j]:.7f}"
                values["gps.lon"] = f"{lat_lon[2][j]:.7f}"
                values["gps.lock"] = next(k for k, v in QGC_GPS_LOCKS.items() if v == 3)
                values["gps.count"] = "10"
        stamp = datetime.fromtimestamp(t, tz=zone).strftime("%Y-%m-%d %H:%M:%S.%f")[:-3]
        rows.append(",".join([stamp, *(values[c] for c in _QGC_COLUMNS)]))
    p = Path(path)
    p.write_text("\n".join(rows) + "\n", encoding="utf-8")
    return p


def write_bluerov_nav(
    d: Dataset, out_dir: str | Path, nav: str, seed: int = 0
) -> tuple[list[Path], str]:
    """Write the navigation of ``d`` as ``nav`` (:data:`NAV_KINDS`) in ``out_dir``; the files
    (the first the one ``[ping360] nav`` names) and the ``[navlog]`` TOML they need ("")."""
    out = Path(out_dir)
    rng = np.random.default_rng([seed, NAV_KINDS.index(nav)])
    first = float(d.dvl.t[0])
    if nav == "tlog":
        return [write_tlog(d, out / "dive.tlog", rng)], ""
    if nav == "dataflash":
        return [write_dataflash(d, out / "00000042.BIN", rng)], ""
    if nav == "dvl_json":
        return [write_dvl_json(d, out / "dvl.json", rng)], ""
    if nav == "dvl_json_v1":
        files = [
            write_dvl_json(d, out / "dvl.json", rng, "json_v1"),
            write_tlog(d, out / "attitude.tlog", rng, corrupt_chunks=0, attitude_only=True),
        ]
        return files, f'\n[navlog]\nstart = "{_unix_iso(first)}"\n'
    if nav == "qgc_csv":
        offset = 2.0
        stamp = datetime.fromtimestamp(first, tz=timezone(timedelta(hours=offset)))
        name = f"{stamp:%Y-%m-%d %H-%M-%S} vehicle1.csv"
        return [write_qgc_csv(d, out / name, offset)], f"\n[navlog]\nutc_offset_h = {offset}\n"
    raise ValueError(f"nav must be one of {NAV_KINDS}, got {nav!r}")


def simulate_bluerov(
    kind: str,
    seed: int,
    out_dir: str | Path,
    nav: str = "tlog",
    duration_s: float | None = None,
    gps: bool = True,
) -> tuple[Path, list[Path]]:
    """Simulate ``kind`` with a Ping360-shaped head and write it as a BlueROV2 logs it: the
    ``.bin`` and the navigation ``nav`` (module docstring), with ``sonarslam.toml`` (``[ping360]
    nav`` the navigation files, ``[navlog]`` where needed) and ``truth.json``. Returns the
    ``.bin`` and the navigation files."""
    out = Path(out_dir)
    log = simulate_ping360(kind, seed, out, duration_s, gps)
    with warnings.catch_warnings():  # the sensors' gaps are the simulator's own
        warnings.simplefilter("ignore", DataWarning)
        dataset = open_dataset(log)  # its navigation from the bag written beside it
    (out / "nav.bag").unlink()
    files, navlog = write_bluerov_nav(dataset, out, nav, seed)
    names = ", ".join(f'"{f.name}"' for f in files)
    nav_toml = names if len(files) == 1 else f"[{names}]"
    toml = dump_dataset_config(dataset.config) + (
        f"\n[ping360]\nnav = {nav_toml}\nspeed_of_sound_mps = 1500.0\n" + navlog
    )
    (out / "sonarslam.toml").write_text(toml, encoding="utf-8")
    return log, files
