"""The fuzzer's inputs (``tests/fuzzing.py``): the reference tokenizer, the seeds (small
slices of the marina's files, or of a short simulated harbour) and the mutations."""

from __future__ import annotations

import json
import math
import os
import random
import re
import warnings
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from sonarslam.datasets.config import MARINA_CONFIG, dump_dataset_config
from sonarslam.datasets.errors import DataWarning
from sonarslam.datasets.marina import read_is_timestamps
from sonarslam.datasets.ping360 import write_ping360_log
from sonarslam.datasets.simulator import simulate
from sonarslam.datasets.source import Dataset, data_root, open_dataset

__all__ = [
    "REF_NUMBER",
    "ref_lines",
    "ref_number",
    "ref_rows",
    "Seed",
    "build_seeds",
    "marina_window",
    "edit_log_rows",
    "Mutation",
    "mutate",
    "write_case",
    "BadBag",
    "bag_seeds",
    "bad_bags",
]

# --- the reference tokenizer: the rules of datasets/logfile.py, written again, plainly --------

REF_NUMBER = re.compile(r"[+-]?(?:[0-9]+(?:\.[0-9]*)?|\.[0-9]+)(?:[eE][+-]?[0-9]+)?")
REF_BREAK = re.compile(rb"\r\n|\r|\n")


def ref_lines(data: bytes) -> tuple[list[bytes], bool]:
    """Physical lines and whether the last ended with a break."""
    if not data:
        return [], True
    parts = REF_BREAK.split(data)
    if parts[-1] == b"":
        return parts[:-1], True
    return parts, False


def ref_number(text: str) -> float | None:
    if not REF_NUMBER.fullmatch(text):
        return None
    v = float(text)
    return v if math.isfinite(v) else None


def ref_rows(
    data: bytes, n_columns: int, delimiter: str | None = None, first_line: int = 1
) -> list[tuple[int, list[float]]]:
    """``(line, values)`` of every line from ``first_line`` on that is a row of ``n_columns``
    finite numbers (lines starting with ``%`` and blank lines are not rows)."""
    lines, _ = ref_lines(data)
    out = []
    for number, raw in enumerate(lines, start=1):
        if number < first_line:
            continue
        text = raw.decode("latin-1").strip(" \t")
        if not text or text.startswith("%"):
            continue
        if delimiter is None:
            fields = [f for f in re.split(r"[ \t]+", text)]
        else:
            fields = [f.strip(" \t") for f in text.split(delimiter)]
        values = [ref_number(f) for f in fields]
        if len(values) == n_columns and all(v is not None for v in values):
            out.append((number, [float(v) for v in values if v is not None]))
    return out


# --- seeds: small slices of real (or simulated) files ---------------------------------------


@dataclass
class Seed:
    """A small input: ``files`` (relative path -> bytes) written into a folder; ``primary`` is
    the file a target reads (or mutates, for a dataset)."""

    name: str
    files: dict[str, bytes]
    primary: str


def _slice_log(path: Path, rows: int, start: int = 0) -> bytes:
    """The ``%`` header and ``rows`` data lines of a log from data line ``start``."""
    raw = path.read_bytes()
    lines = raw.splitlines(keepends=True)
    header = [ln for ln in lines if ln.startswith(b"%") or not ln.strip()][:12]
    data = [ln for ln in lines if ln.strip() and not ln.startswith(b"%")]
    body = data[start : start + rows]
    if body and not body[-1].endswith((b"\n", b"\r")):
        body[-1] += b"\r\n"
    return b"".join(header + body)


def _pcd_slice(path: Path, points: int) -> bytes:
    lines = path.read_bytes().split(b"\n")
    k = next(i for i, ln in enumerate(lines) if ln.startswith(b"DATA"))
    head = [b"POINTS %d" % points if ln.startswith(b"POINTS") else ln for ln in lines[: k + 1]]
    head = [b"WIDTH %d" % points if ln.startswith(b"WIDTH") else ln for ln in head]
    return b"\n".join(head + lines[k + 1 : k + 1 + points]) + b"\n"


def _marina_seeds(root: Path) -> dict[str, Seed]:
    logs, kf = root / "logs", root / "keyframes"

    def log(suffix: str) -> Path:
        return next(logs.glob(f"*_{suffix}.log"))

    seeds = {
        "dvl": Seed("marina DVL", {"a_DVL.log": _slice_log(log("DVL"), 30)}, "a_DVL.log"),
        "mti": Seed("marina MTi", {"a_MTi.log": _slice_log(log("MTi"), 40)}, "a_MTi.log"),
        "dgps": Seed("marina DGPS", {"a_DGPS.log": _slice_log(log("DGPS"), 30)}, "a_DGPS.log"),
        "stamps": Seed(
            "marina IS_timestamps",
            {"a_IS_timestamps.log": _slice_log(log("IS_timestamps"), 40)},
            "a_IS_timestamps.log",
        ),
        "setup": Seed("marina SETUP", {"a_SETUP.log": log("SETUP").read_bytes()}, "a_SETUP.log"),
        "pcd": Seed("marina PCD", {"k.pcd": _pcd_slice(kf / "pclKeyFrame14.pcd", 40)}, "k.pcd"),
        "csv": Seed(
            "marina keyframe CSV",
            {
                "keyFrameTimeStamps.csv": b"".join(
                    (kf / "keyFrameTimeStamps.csv").read_bytes().splitlines(keepends=True)[:8]
                )
            },
            "keyFrameTimeStamps.csv",
        ),
    }
    seeds["dataset"] = _marina_dataset_seed(root)
    return seeds


def marina_window(
    root: Path, t0_s: float, t1_s: float, pcd_points: int | None = None
) -> dict[str, bytes]:
    """The files of the marina between two times (Unix s): the logs' rows inside (headers
    kept, CRLF as the originals), the keyframes whose scans lie inside, their IS_timestamps
    rows, the SETUP log; ``pcd_points`` thins each PCD to that many points (None: all)."""
    logs, kf = root / "logs", root / "keyframes"
    csv_lines = (kf / "keyFrameTimeStamps.csv").read_text().splitlines()

    def window(suffix: str) -> bytes:
        raw = next(logs.glob(f"*_{suffix}.log")).read_bytes()
        out = []
        for ln in raw.splitlines(keepends=True):
            s = ln.strip()
            if not s or s.startswith(b"%"):
                out.append(ln)
            elif t0_s <= float(s.split()[0]) <= t1_s:
                out.append(ln if ln.endswith((b"\n", b"\r")) else ln + b"\r\n")
        return b"".join(out)

    scans = [
        line
        for line in csv_lines[1:]
        if t0_s <= float(line.split(",")[1]) and float(line.split(",")[2]) <= t1_s - 1.0
    ]
    files = {
        f"logs/m_{suffix}.log": window(suffix) for suffix in ("DVL", "MTi", "DGPS", "IS_timestamps")
    }
    files["logs/m_SETUP.log"] = next(logs.glob("*_SETUP.log")).read_bytes()
    files["keyframes/keyFrameTimeStamps.csv"] = "\n".join([csv_lines[0], *scans, ""]).encode()
    for line in scans:
        k = line.split(",")[0]
        pcd = kf / f"pclKeyFrame{k}.pcd"
        files[f"keyframes/pclKeyFrame{k}.pcd"] = (
            pcd.read_bytes() if pcd_points is None else _pcd_slice(pcd, pcd_points)
        )
    return files


def _marina_dataset_seed(root: Path) -> Seed:
    """A 30 s marina dataset around keyframe 14 (thinned PCD: the polar grid kept)."""
    csv_lines = (root / "keyframes" / "keyFrameTimeStamps.csv").read_text().splitlines()
    _, begin, end = csv_lines[14].split(",")
    files = marina_window(root, float(begin) - 5.0, float(end) + 10.0, pcd_points=60)
    return Seed("marina 30 s dataset", files, "logs/m_DVL.log")


def _simulated_seeds(work: Path) -> dict[str, Seed]:
    """Seeds from a 20 s simulated harbour (and synthetic keyframes on its head's grid)."""
    src = simulate("harbour", seed=5, out_dir=work / "sim", duration_s=20.0)
    prefix = "sim_harbour_5"

    def log(suffix: str, rows: int) -> bytes:
        return _slice_log(src / f"{prefix}_{suffix}.log", rows)

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DataWarning)  # its DVL dropout is simulated
        head = open_dataset(src).config.sonar
    stamps = read_is_timestamps(src / f"{prefix}_IS_timestamps.log")
    n = int(round(2 * math.pi / head.step_rad))
    pts = [
        (r * math.cos(j * head.step_rad), r * math.sin(j * head.step_rad))
        for j, b in ((j, 5 + (7 * j) % 40) for j in range(0, n, 5))
        for r in [float(head.bin_range_m(b))]
    ]
    pcd = (
        "VERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\n"
        f"WIDTH {len(pts)}\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS {len(pts)}\nDATA ascii\n"
        + "".join(f"{x:.4f} {y:.4f} 0.0000 \n" for x, y in pts)
    ).encode()
    csv = f"keyFrame,keyFrameBeginning,keyFrameEnd\n1,{stamps[0]:.5f},{stamps[n]:.5f}\n".encode()
    is_log = b"".join((src / f"{prefix}_IS.log").read_bytes().splitlines(keepends=True)[:20])
    dataset_files = {
        p.name: (p.read_bytes() if p.name != f"{prefix}_IS.log" else _head_beams(p, 120))
        for p in src.iterdir()
        if p.is_file()
    }
    return {
        "dvl": Seed("simulated DVL", {"a_DVL.log": log("DVL", 30)}, "a_DVL.log"),
        "mti": Seed("simulated MTi", {"a_MTi.log": log("MTi", 40)}, "a_MTi.log"),
        "dgps": Seed("simulated DGPS", {"a_DGPS.log": log("DGPS", 30)}, "a_DGPS.log"),
        "stamps": Seed(
            "simulated IS_timestamps",
            {"a_IS_timestamps.log": log("IS_timestamps", 40)},
            "a_IS_timestamps.log",
        ),
        "setup": Seed("simulated SETUP", {"a_SETUP.log": log("SETUP", 1)}, "a_SETUP.log"),
        "pcd": Seed("synthetic PCD", {"k.pcd": pcd}, "k.pcd"),
        "csv": Seed(
            "synthetic keyframe CSV", {"keyFrameTimeStamps.csv": csv}, "keyFrameTimeStamps.csv"
        ),
        "dataset": Seed("simulated 20 s dataset", dataset_files, f"{prefix}_DVL.log"),
        "is_log": Seed("simulated IS log", {"a_IS.log": is_log}, "a_IS.log"),
    }


def _head_beams(path: Path, beams: int) -> bytes:
    lines = path.read_bytes().splitlines(keepends=True)
    return b"".join(lines[: 7 + beams])


def _ping360_seed(work: Path) -> Seed:
    """A Ping Viewer log of 12 beams of 200 samples (sonarslam's writer, as Ping Viewer lays
    it out), elapsed stamps 70 ms apart."""
    name = "20040825-173500000.bin"
    rng = random.Random(360)
    bins = np.array([[rng.randrange(256) for _ in range(200)] for _ in range(12)], np.uint8)
    path = work / name
    write_ping360_log(path, np.arange(12) * 70 + 400, (np.arange(12) * 2) % 400, bins, 900)
    return Seed("Ping Viewer .bin", {name: path.read_bytes()}, name)


def build_seeds(work: Path) -> dict[str, Seed]:
    """Every target's seed: the marina's slices when present (the raw IS log, the TOML and the
    truth from the simulator, which the marina has not), else the simulated ones."""
    sim = _simulated_seeds(work)
    root = data_root()
    seeds = dict(sim)
    if root is not None and (root / "marina").is_dir():
        seeds.update(_marina_seeds(root / "marina"))
        seeds.update({f"sim_{k}": v for k, v in sim.items() if k in seeds and seeds[k] is not v})
    seeds["toml"] = Seed(
        "sonarslam.toml",
        {"sonarslam.toml": dump_dataset_config(MARINA_CONFIG).encode()},
        "sonarslam.toml",
    )
    truth = json.loads(sim["dataset"].files["truth.json"])
    truth["body_poses"]["rows"] = truth["body_poses"]["rows"][:40]
    truth["beams"]["rows"] = truth["beams"]["rows"][:10]
    seeds["truth"] = Seed(
        "truth.json", {"truth.json": json.dumps(truth, indent=0).encode()}, "truth.json"
    )
    seeds.update(bag_seeds(work, sim["dataset"]))
    seeds["ping360"] = _ping360_seed(work)
    seeds["extractor_toml"] = Seed(
        "extract --config",
        {"x.toml": b"[extractor]\nmin_votes = 12\nmax_range_m = 25.0\n"},
        "x.toml",
    )
    return seeds


def edit_log_rows(path: Path, edit: Callable[[float, list[str]], list[list[str]]]) -> None:
    """Rewrite the data rows of a log in place: ``edit(t - t_first, fields)`` returns the rows
    (lists of fields) to write instead of the row (none: drop it); headers kept, CRLF ends."""
    raw = path.read_bytes().decode("latin-1").splitlines()
    t_first = None
    out = []
    for line in raw:
        if not line.strip() or line.startswith("%"):
            out.append(line)
            continue
        fields = line.split()
        t = float(fields[0])
        t_first = t if t_first is None else t_first
        out += ["\t".join(f) for f in edit(t - t_first, fields)]
    path.write_bytes(("\r\n".join(out) + "\r\n").encode("latin-1"))


# --- mutations --------------------------------------------------------------------------------

INTERESTING_BYTES = (
    bytes([0x00, 0x09, 0x0A, 0x0B, 0x0C, 0x0D, 0x1C, 0x1D, 0x1E, 0x1F, 0x20, 0x85, 0xA0, 0xFF])
    + b"-+.eE09,%#_"
)
TOKENS = [
    "nan",
    "NaN",
    "inf",
    "-inf",
    "Infinity",
    "1e308",
    "-1e308",
    "1e999",
    "1e-400",
    "",
    "1_0",
    "0x10",
    "\u0661\u0662",
    "\uff11\uff12",
    "+",
    "-",
    ".",
    "1e",
    "1.",
    "--1",
    "1,5",
    "12 34",
    "9" * 400,
    "0",
    "-0",
    "14.5",
    "1e300",
    "4294967296",
    "-1",
    "99999",
    "0.0",
    "1e9",
    "5000",
    "-5000",
    "0.5",
    "2",
    "360.5",
    "6000.5",
    "9000.0",
]
SPECIAL_FILES = ("directory", "fifo", "dev_zero", "symlink_loop", "empty", "random_bytes")


@dataclass
class Mutation:
    """What was done: ``kind`` (``bytes``, ``field``, ``lines``, ``cut``, ``special``,
    ``none``), a description, the mutated bytes (None for a special file), which file."""

    kind: str
    what: str
    data: bytes | None
    file: str
    special: str | None = None


def _data_line_spans(data: bytes) -> list[tuple[int, int]]:
    """Byte spans of the lines that are not headers."""
    spans, pos = [], 0
    for m in REF_BREAK.finditer(data + b"\n"):
        line = data[pos : m.start()]
        if line.strip() and not line.lstrip().startswith(b"%"):
            spans.append((pos, m.start()))
        pos = m.end()
    return spans


def mutate(data: bytes, rng: random.Random, file: str, special: bool = True) -> Mutation:
    """One random mutation of ``data``."""
    r = rng.random()
    if special and r < 0.04:
        kind = rng.choice(SPECIAL_FILES)
        return Mutation("special", kind, None, file, kind)
    if r < 0.25 and data:
        return _byte_mutation(data, rng, file)
    if r < 0.55 and data:
        return _field_mutation(data, rng, file)
    if r < 0.8 and data:
        return _line_mutation(data, rng, file)
    if data:
        cut = rng.randrange(0, len(data))
        if rng.random() < 0.6:  # cut inside the last line
            start = max(data.rstrip(b"\r\n").rfind(b"\n") + 1, 0)
            cut = rng.randrange(start, len(data)) if start < len(data) else cut
        return Mutation("cut", f"cut at byte {cut} of {len(data)}", data[:cut], file)
    return Mutation("none", "empty seed", data, file)


def _byte_mutation(data: bytes, rng: random.Random, file: str) -> Mutation:
    pos = rng.randrange(len(data))
    b = rng.choice(INTERESTING_BYTES) if rng.random() < 0.8 else rng.randrange(256)
    op = rng.choice(("replace", "insert", "delete"))
    if op == "replace":
        new = data[:pos] + bytes([b]) + data[pos + 1 :]
    elif op == "insert":
        new = data[:pos] + bytes([b]) + data[pos:]
    else:
        new = data[:pos] + data[pos + 1 :]
    return Mutation("bytes", f"{op} 0x{b:02X} at byte {pos}", new, file)


def _field_mutation(data: bytes, rng: random.Random, file: str) -> Mutation:
    spans = _data_line_spans(data)
    if not spans:
        return _byte_mutation(data, rng, file)
    a, b = rng.choice(spans)
    line = data[a:b]
    fields = [m.span() for m in re.finditer(rb"[^ \t,=]+", line)]
    if not fields:
        return _byte_mutation(data, rng, file)
    fa, fb = rng.choice(fields)
    old = line[fa:fb]
    if rng.random() < 0.3 and ref_number(old.decode("latin-1")) is not None:
        factor = rng.choice((-1.0, 1e3, 1e6, 1e-3, 10.0, 1e300))
        token = repr(float(old) * factor).encode()
    else:
        token = rng.choice(TOKENS).encode("utf-8")
    new = data[: a + fa] + token + data[a + fb :]
    return Mutation("field", f"field {old[:20]!r} -> {token[:20]!r}", new, file)


def _line_mutation(data: bytes, rng: random.Random, file: str) -> Mutation:
    lines = data.splitlines(keepends=True)
    i = rng.randrange(len(lines))
    op = rng.choice(
        ("duplicate", "delete", "swap", "blank", "comment", "crlf", "lone_cr", "header_dup", "gap")
    )
    if op == "gap":  # a sensor silent for a while
        n = rng.randrange(2, max(len(lines) // 2, 3))
        del lines[i : i + n]
        return Mutation("lines", f"delete lines {i + 1}-{i + n}", b"".join(lines), file)
    if op == "duplicate":
        lines.insert(i, lines[i])
    elif op == "delete":
        del lines[i]
    elif op == "swap":
        j = rng.randrange(len(lines))
        lines[i], lines[j] = lines[j], lines[i]
    elif op == "blank":
        lines.insert(i, b"\r\n")
    elif op == "comment":
        lines.insert(i, b"% inserted comment \xe9\r\n")
    elif op == "crlf":
        return Mutation(
            "lines",
            "CRLF <-> LF",
            data.replace(b"\r\n", b"\n") if b"\r\n" in data else data.replace(b"\n", b"\r\n"),
            file,
        )
    elif op == "lone_cr":
        return Mutation(
            "lines",
            "line ends as lone CR",
            data.replace(b"\r\n", b"\r").replace(b"\n", b"\r"),
            file,
        )
    else:
        lines.insert(0, lines[0])
    return Mutation("lines", f"{op} line {i + 1}", b"".join(lines), file)


def write_case(folder: Path, seed: Seed, m: Mutation) -> Path:
    """Write the seed with its mutation into ``folder``; returns the primary path."""
    for rel, content in seed.files.items():
        p = folder / rel
        p.parent.mkdir(parents=True, exist_ok=True)
        p.write_bytes(m.data if rel == m.file and m.data is not None else content)
    target = folder / m.file
    if m.special is not None:
        target.unlink()
        if m.special == "directory":
            target.mkdir()
        elif m.special == "fifo":
            os.mkfifo(target)
        elif m.special == "dev_zero":
            target.symlink_to("/dev/zero")
        elif m.special == "symlink_loop":
            target.symlink_to(target.name)
        elif m.special == "empty":
            target.write_bytes(b"")
        else:
            target.write_bytes(bytes(random.Random(len(m.file)).randrange(256) for _ in range(300)))
    return folder / seed.primary


# --- ROS bags: seeds for the mutations, and the named bad bags ---------------------------------

#: Seconds of the simulated harbour a bag seed holds (small: every case writes and reads it)
BAG_SEED_S = 4.0


def _seed_dataset(work: Path, files: dict[str, bytes]) -> Dataset:
    """The simulated dataset seed's first :data:`BAG_SEED_S` seconds, opened."""
    from dataclasses import replace

    from sonarslam.datasets.records import AttitudeSeries, DvlSeries

    folder = work / "bag_source"
    folder.mkdir(parents=True, exist_ok=True)
    for name, data in files.items():
        (folder / name).write_bytes(data)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DataWarning)
        d = open_dataset(folder)
    t0 = d.nav_span_s[0]
    a, v = d.attitude, d.dvl
    ka, kv = a.t < t0 + BAG_SEED_S, v.t < t0 + BAG_SEED_S
    return replace(
        d,
        beams=d.beams.between(0.0, t0 + BAG_SEED_S),
        attitude=AttitudeSeries(a.t[ka], a.yaw_rad[ka], a.yaw_rate_rad_per_s[ka]),
        dvl=DvlSeries(v.t[kv], v.v_mps[kv], v.valid[kv], v.heading_rad[kv]),
        gps=None,
    )


def _files(root: Path) -> dict[str, bytes]:
    return {
        str(f.relative_to(root)): f.read_bytes() for f in sorted(root.rglob("*")) if f.is_file()
    }


def bag_seeds(work: Path, dataset_seed: Seed) -> dict[str, Seed]:
    """A few seconds of the simulated harbour as a ROS 1 bag, a ROS 2 MCAP bag and a ROS 2
    sqlite3 bag (each with the run's sonarslam.toml), for the ``open_bag`` targets."""
    from sonarslam.datasets.rosbag import bag_config, write_bag

    d = _seed_dataset(work, dataset_seed.files)
    toml = dump_dataset_config(bag_config(d.config)).encode()  # REP-103 angles
    out = {}
    for kind in ("ros1", "mcap", "sqlite3"):
        folder = work / f"bag_{kind}"
        folder.mkdir(parents=True, exist_ok=True)
        path = write_bag(d, folder / ("run.bag" if kind == "ros1" else "bag"), kind)
        (folder if kind == "ros1" else path).joinpath("sonarslam.toml").write_bytes(toml)
        files = _files(folder)
        primary = (
            "run.bag" if kind == "ros1" else next(f for f in files if f.endswith(("mcap", "db3")))
        )
        out[f"bag_{kind}"] = Seed(f"simulated {kind} bag", files, primary)
    return out


@dataclass
class BadBag:
    """A bag made bad on purpose and what reading it must give: ``expect`` "error" (a
    DataError whose message matches every regular expression of ``says``: the file, the
    topic, the message's index) or "warning" (read, with ``count`` of the report's counts
    above zero and a warning matching ``says``) or "read" (read as it is)."""

    name: str
    path: Path
    expect: str
    says: tuple[str, ...]
    count: str = ""
    topics: Path | None = None


def bad_bags(work: Path, seed: Seed) -> list[BadBag]:
    """The bad bags of issue 30 (custom types with no definition, repeated, out-of-order and
    jumping stamps, a wrong type on a role topic, files cut short), made from a seed of
    :func:`bag_seeds` (``bag_ros1``) and the dataset it was written from."""
    import sqlite3

    from rosbags.rosbag1 import Writer as Writer1
    from rosbags.rosbag2 import StoragePlugin
    from rosbags.rosbag2 import Writer as Writer2
    from rosbags.typesys import get_types_from_msg

    from sonarslam.datasets.rosbag import WRITTEN_TOPICS, _messages, _stamp_of, _typestore

    work.mkdir(parents=True, exist_ok=True)
    src = work / "src"
    write_case(src, seed, Mutation("none", "", None, seed.primary))
    from sonarslam.datasets.rosbag import open_bag

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DataWarning)
        d = open_bag(src / "run.bag")
    store = _typestore()
    store.register(get_types_from_msg("std_msgs/Header header\nfloat64 x\n", "acme_msgs/msg/Thing"))
    types = {
        "sonar": "sensor_msgs/msg/LaserScan",
        "dvl": "geometry_msgs/msg/TwistWithCovarianceStamped",
        "imu": "sensor_msgs/msg/Imu",
    }

    def write(
        name: str, kind: str, edit: Callable[[str, int, float], list[float]], extra: bool = False
    ) -> Path:
        """The seed's messages, each written at the stamps ``edit(role, index, t)`` gives
        (none: dropped; two: repeated), received at ``t``; ``extra``: an /acme topic of a
        custom type beside them."""
        path = work / name
        counts = dict.fromkeys(types, 0)
        ser = store.serialize_ros1 if kind == "ros1" else store.serialize_cdr
        w: Any = (
            Writer1(path)
            if kind == "ros1"
            else Writer2(path, version=9, storage_plugin=StoragePlugin.SQLITE3)
        )
        with w:
            conns = {
                r: w.add_connection(WRITTEN_TOPICS[r], ty, typestore=store)
                for r, ty in types.items()
            }
            acme = (
                w.add_connection("/acme", "acme_msgs/msg/Thing", typestore=store) if extra else None
            )
            T = store.types
            for t, role, msg in _messages(store, d):
                if role not in conns:
                    continue
                for stamp in edit(role, counts[role], t):
                    msg.header.stamp = _stamp_of(store, stamp)
                    w.write(conns[role], int(round(t * 1e9)), ser(msg, types[role]))
                counts[role] += 1
                if acme is not None and role == "imu":
                    thing = T["acme_msgs/msg/Thing"](header=msg.header, x=1.0)
                    w.write(acme, int(round(t * 1e9)), ser(thing, "acme_msgs/msg/Thing"))
        if kind == "sqlite3":  # a ROS 2 Humble bag: no definitions stored
            db = sqlite3.connect(next(path.glob("*.db3")))
            db.execute("DELETE FROM message_definitions")
            db.commit()
            db.close()
        return path

    same: Callable[[str, int, float], list[float]] = lambda role, i, t: [t]  # noqa: E731
    out = [
        BadBag(
            "custom type with no definition beside the roles",
            write("acme", "sqlite3", same, extra=True),
            "read",
            (),
        ),
    ]
    topics = work / "acme_topics.toml"
    topics.write_text('[topics]\ndvl = "/acme"\n')
    out.append(
        BadBag(
            "custom type with no definition on a role topic",
            out[0].path,
            "error",
            (r"acme", r"topic /acme is acme_msgs/msg/Thing, which cannot be the dvl"),
            topics=topics,
        )
    )
    out.append(
        BadBag(
            "repeated stamps",
            write("repeat.bag", "ros1", lambda r, i, t: [t, t] if r == "dvl" and i == 3 else [t]),
            "warning",
            (
                r"repeat.bag: topic /dvl/twist \(dvl\): 1 message\(s\) with the stamp of the"
                r" one before \(the first: message 4\)",
                r"repeat.bag: dropped 1 row\(s\) repeating a stamp",
            ),
            count="dvl_repeated",
        )
    )
    out.append(
        BadBag(
            "out-of-order stamps",
            write("ooo.bag", "ros1", lambda r, i, t: [t + 0.15] if r == "imu" and i == 10 else [t]),
            "warning",
            (r"ooo.bag: topic /imu/data \(imu\): 1 message\(s\) stamped earlier.*message 11",),
            count="imu_out_of_order",
        )
    )
    out.append(
        BadBag(
            "a clock jump",
            write(
                "jump.bag", "ros1", lambda r, i, t: [t + 3600.0] if r == "imu" and i >= 20 else [t]
            ),
            "error",
            (r"jump.bag", r"topic /imu/data \(imu\) message 20: its stamp jumps \+3600"),
        )
    )
    wrong = work / "wrong_topics.toml"
    wrong.write_text('[topics]\nsonar = "/imu/data"\n')
    out.append(
        BadBag(
            "a wrong type on a role topic",
            src / "run.bag",
            "error",
            (r"run.bag", r"topic /imu/data is sensor_msgs/msg/Imu, which cannot be the sonar"),
            topics=wrong,
        )
    )
    for kind in ("ros1", "mcap", "sqlite3"):
        from sonarslam.datasets.rosbag import write_bag

        (work / f"full_{kind}").mkdir(exist_ok=True)
        full = write_bag(d, work / f"full_{kind}" / ("run.bag" if kind == "ros1" else "bag"), kind)
        data_file = (
            full
            if kind == "ros1"
            else next(f for f in full.iterdir() if f.suffix in (".mcap", ".db3"))
        )
        data = data_file.read_bytes()
        data_file.write_bytes(data[: len(data) * 2 // 3])
        out.append(BadBag(f"truncated {kind}", full, "error", (re.escape(str(full)),)))
    return out
