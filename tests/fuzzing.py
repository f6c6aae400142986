"""The project's own fuzzer of bad input: seeded mutations of small real slices (the marina
when ``$SONARSLAM_DATA`` holds it, a short simulated harbour otherwise), run through every
reader, the configuration loaders and the dataset opener, each judged by an oracle.

Used by ``tests/test_fuzz_readers.py`` (a few hundred cases per target, in ``make test``) and by
``benchmarks/fuzz_readers.py`` (the long mode, ``--cases 20000``, with the results table).

A case is a seed file (or folder), one mutation (bytes, a field, lines, a cut, or the file
replaced by a directory, a FIFO, a symlink to ``/dev/zero``, a symlink loop...) and a target.
Its outcome is one of

* ``accepted``: the target returned; the oracle then checks what it returned: every value
  finite; the rows exactly those a reference tokenizer (written here, independently, from the
  rules of :mod:`datasets.logfile`) finds in the mutated text; for a file cut short, every
  value it kept equal to the uncut file's; for a dataset, the gates' promises (no DVL speed
  over the limit, no GPS fix at 0/0 or repeated, no unexplained AHRS jump...);
* ``data_error``: a :class:`datasets.errors.DataError` (or for settings a
  :class:`datasets.settings.SettingError`); the oracle checks that it names the mutated file
  and, when it names a line, that the line is one the mutation changed (or the data line
  after one: time going backwards is seen there);
* ``foreign``: any other exception (a bug); ``hang``: no answer within the time limit.
"""

from __future__ import annotations

import difflib
import json
import math
import os
import random
import re
import shutil
import signal
import tempfile
import tomllib
import traceback
import warnings
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from datasets.config import _SCHEMA as TOML_SCHEMA  # what each key of the file sets
from datasets.config import MARINA_CONFIG, dump_dataset_config, load_dataset_config
from datasets.errors import DataError, DataWarning
from datasets.islog import read_is_log
from datasets.keyframes import read_keyframe_times, read_pcd_xy
from datasets.marina import read_dgps, read_dvl, read_is_timestamps, read_mti, read_setup
from datasets.settings import SettingError
from datasets.simulator import simulate
from datasets.source import Dataset, data_root, open_dataset, read_truth
from features.geometry import wrap_angle
from slam.run.presets import (
    apply_overrides,
    backend_config,
    check_settings,
    extractor_config,
    parse_settings,
)

__all__ = [
    "Seed",
    "Outcome",
    "TARGETS",
    "build_seeds",
    "run_case",
    "fuzz",
    "summarise",
    "marina_window",
    "check_dataset",
    "edit_log_rows",
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


# --- running a case, with its oracle ----------------------------------------------------------


@dataclass
class Outcome:
    """How a case ended and what the oracle found (``problems``: empty when all is well)."""

    target: str
    status: str  # accepted | data_error | foreign | hang
    mutation: str
    problems: list[str] = field(default_factory=list)
    message: str = ""
    named_line: bool = False


class _Hang(Exception):
    pass


@contextmanager
def _time_limit(seconds: float) -> Iterator[None]:
    def alarm(signum: int, frame: Any) -> None:
        raise _Hang()

    old = signal.signal(signal.SIGALRM, alarm)
    signal.setitimer(signal.ITIMER_REAL, seconds)
    try:
        yield
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0.0)
        signal.signal(signal.SIGALRM, old)


def changed_lines(original: bytes, mutated: bytes) -> set[int]:
    """Physical lines of ``mutated`` that the mutation touched, and the line after each
    (an order error is seen at the next row); line 1 when nothing is comparable."""
    a, _ = ref_lines(original)
    b, _ = ref_lines(mutated)
    out: set[int] = set()
    for tag, _i1, _i2, j1, j2 in difflib.SequenceMatcher(None, a, b, autojunk=False).get_opcodes():
        if tag == "equal":
            continue
        for j in range(j1, max(j2, j1 + 1)):
            out.add(j + 1)
        if tag == "delete" and j1 > 0:  # the line before a deletion now ends where it was
            out.add(j1)
    data_lines = [
        i + 1 for i, ln in enumerate(b) if ln.strip() and not ln.lstrip().startswith(b"%")
    ]
    for n in list(out):  # the next data line after a change (time going backwards)
        later = [d for d in data_lines if d > n]
        if later:
            out.add(later[0])
    return out or {1}


def _check_error(exc: DataError, path: Path, root: Path, m: Mutation, seed: Seed) -> list[str]:
    """The error names the mutated input, and a line the mutation changed (a TOML or JSON
    parser may see a change only further on: any later line is right there)."""
    problems = []
    late_ok = m.file.endswith((".toml", ".json"))
    named = Path(exc.path)
    if not (named == path or root in named.parents or named == root):
        problems.append(f"names {named}, not the mutated input")
    if str(exc.path) not in str(exc):
        problems.append("message does not name the file")
    if exc.line is not None:
        if m.data is not None and named.resolve() == (root / m.file).resolve():
            ok = changed_lines(seed.files[m.file], m.data)
            if exc.line not in ok and not (late_ok and exc.line >= min(ok)):
                problems.append(f"names line {exc.line}, the mutation changed {sorted(ok)[:6]}")
        if f":{exc.line}:" not in str(exc):
            problems.append("message does not name the line")
    return problems


def run_case(target: str, seed: Seed, m: Mutation, work: Path, limit_s: float = 10.0) -> Outcome:
    """Write the case into a fresh folder under ``work``, run the target, judge it."""
    folder = Path(tempfile.mkdtemp(dir=work))
    try:
        path = write_case(folder, seed, m)
        spec = TARGETS[target]
        out = Outcome(target, "accepted", f"{m.kind}: {m.what}")
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            try:
                with _time_limit(limit_s):
                    result = spec.read(path)
            except _Hang:
                out.status = "hang"
                return out
            except (DataError, SettingError) as exc:
                out.status = "data_error"
                out.message = str(exc)
                if isinstance(exc, DataError):
                    out.named_line = exc.line is not None
                    out.problems += _check_error(exc, path, folder, m, seed)
                return out
            except Exception as exc:  # the oracle's very point: anything else is a bug
                out.status = "foreign"
                out.message = f"{type(exc).__name__}: {exc}"[:300]
                out.problems.append(traceback.format_exc(limit=-3)[-600:])
                return out
        foreign_warnings = [w for w in caught if not issubclass(w.category, DataWarning)]
        if foreign_warnings:
            out.problems.append(
                f"warning {foreign_warnings[0].category.__name__}: {foreign_warnings[0].message}"
            )
        original = seed.files.get(m.file, b"")
        out.problems += spec.check(
            result, m.data if m.data is not None else b"", original, m, folder
        )
        return out
    finally:
        _unlink_tree(folder)


def _unlink_tree(folder: Path) -> None:
    shutil.rmtree(folder, ignore_errors=True)  # unlinks FIFOs and symlinks, follows none


# --- oracles per target -----------------------------------------------------------------------


def _finite(*arrays: Any) -> list[str]:
    return [
        "returned a value that is not finite"
        for a in arrays
        if not np.all(np.isfinite(np.asarray(a, dtype=np.float64)))
    ][:1]


def _match_rows(
    got: np.ndarray,
    mutated: bytes,
    original: bytes,
    m: Mutation,
    n_columns: int,
    used: tuple[int, ...],
    convert: Callable[[np.ndarray], np.ndarray],
    delimiter: str | None = None,
    first_line: int = 1,
) -> list[str]:
    """The rows returned (``got``, converted columns) against the reference rows of the
    mutated text; for a cut file, against the uncut file's rows at the same lines."""
    ref = ref_rows(mutated, n_columns, delimiter, first_line)
    _, terminated = ref_lines(mutated)
    n_lines = len(ref_lines(mutated)[0])
    expected = np.array([v for _, v in ref]) if ref else np.zeros((0, n_columns))
    rows = [r for r, _ in ref]
    if got.shape[0] == expected.shape[0] - 1 and not terminated and rows and rows[-1] == n_lines:
        expected, rows = expected[:-1], rows[:-1]  # the open-ended last line, skipped
    if got.shape[0] != expected.shape[0]:
        return [f"returned {got.shape[0]} rows, the reference finds {expected.shape[0]}"]
    want = convert(expected)
    if not np.array_equal(got, want, equal_nan=False):
        bad = int(np.flatnonzero(~np.all(np.isclose(got, want, rtol=0, atol=0), axis=1))[0])
        return [f"row at line {rows[bad]}: returned {got[bad][:4]}, the text says {want[bad][:4]}"]
    if m.kind == "cut":  # every kept value equals the uncut file's at its line
        whole = dict(ref_rows(original, n_columns, delimiter, first_line))
        for line, values in zip(rows, expected, strict=True):
            if line in whole and any(values[c] != whole[line][c] for c in used):
                return [f"line {line} was cut short and its value kept ({values[list(used)][:4]})"]
    return []


def _wrap(a: np.ndarray) -> np.ndarray:
    return np.asarray(wrap_angle(a))


def _check_dvl(
    result: Any, mutated: bytes, original: bytes, m: Mutation, folder: Path
) -> list[str]:
    got = np.column_stack([result.t, result.v_mps, result.valid, result.heading_rad])
    problems = _finite(got)
    if problems:
        return problems
    ref = np.array([v for _, v in ref_rows(mutated, 32)]) if ref_rows(mutated, 32) else None
    if ref is not None and (
        np.any(~np.isin(ref[:, 14], (0.0, 1.0))) or np.any(np.abs(ref[:, 22]) > 360)
    ):
        if ref.shape[0] == got.shape[0]:
            return ["accepted a status other than 0/1 or a heading beyond 360 deg"]

    def conv(e: np.ndarray) -> np.ndarray:
        heading = _wrap(np.pi / 2 - np.deg2rad(e[:, 22]))
        return np.column_stack([e[:, 0], e[:, 11:13] / 100.0, e[:, 14] == 1.0, heading])

    return _match_rows(got, mutated, original, m, 32, (0, 11, 12, 14, 22), conv)


def _check_mti(
    result: Any, mutated: bytes, original: bytes, m: Mutation, folder: Path
) -> list[str]:
    got = np.column_stack([result.t, result.yaw_rad, result.yaw_rate_radps])
    problems = _finite(got)
    if problems:
        return problems

    def conv(e: np.ndarray) -> np.ndarray:
        return np.column_stack([e[:, 0], _wrap(np.pi / 2 - np.deg2rad(e[:, 3])), -e[:, 6]])

    return _match_rows(got, mutated, original, m, 10, (0, 3, 6), conv)


def _check_dgps(
    result: Any, mutated: bytes, original: bytes, m: Mutation, folder: Path
) -> list[str]:
    problems = _finite(result.t, result.en_m)
    if problems:
        return problems
    got = np.column_stack([result.t, result.fix])

    def conv(e: np.ndarray) -> np.ndarray:
        zero = (e[:, 1] == 0) & (e[:, 2] == 0)
        return np.column_stack([e[:, 0], np.isin(e[:, 3], (1, 2, 3, 4, 5)) & ~zero])

    out = _match_rows(got, mutated, original, m, 10, (0, 1, 2, 3), conv)
    ref = ref_rows(mutated, 10)
    for _, v in ref:
        for c in (1, 2):
            minutes = abs(v[c]) - 100 * math.floor(abs(v[c]) / 100)
            if minutes >= 60 and len(ref) == got.shape[0]:
                return out + ["accepted minutes >= 60"]
    return out


def _check_stamps(
    result: Any, mutated: bytes, original: bytes, m: Mutation, folder: Path
) -> list[str]:
    got = np.asarray(result)[:, None]
    return _finite(got) or _match_rows(got, mutated, original, m, 2, (0,), lambda e: e[:, :1])


def _check_setup(
    result: Any, mutated: bytes, original: bytes, m: Mutation, folder: Path
) -> list[str]:
    range_m, bin_m, step = result
    problems = _finite([range_m, bin_m, step])
    if problems:
        return problems
    whole = read_setup_reference(original)
    if m.kind == "cut" and whole is not None and (range_m, bin_m) != whole[:2]:
        return [f"cut SETUP accepted as {result}"]
    if m.kind == "cut" and whole is not None and abs(step - whole[2]) > 1e-12:
        return [f"cut SETUP step accepted as {step} (was {whole[2]})"]
    beams = 2 * math.pi / step
    if (
        abs(beams - round(beams)) > 1e-6
        or abs(range_m / bin_m - round(range_m / bin_m)) > 1e-6 * range_m / bin_m
    ):
        return [f"SETUP {result} is not whole bins and beams"]
    return []


def read_setup_reference(data: bytes) -> tuple[float, float, float] | None:
    rows = ref_rows(data, 3)
    if len(rows) != 1:
        return None
    r, b, s = rows[0][1]
    beams = 2 * math.pi / s
    return (r, b, 2 * math.pi / round(beams)) if beams < 1e9 and round(beams) > 0 else None


def _check_is_log(
    result: Any, mutated: bytes, original: bytes, m: Mutation, folder: Path
) -> list[str]:
    if not result:
        return ["no beams, no error"]
    n_bins = result[0].intensities.size
    got = np.array(
        [[b.t, b.transducer_angle_rad, *b.intensities] for b in result], dtype=np.float64
    )
    problems = _finite(got)
    if problems:
        return problems
    return _match_rows(
        got,
        mutated,
        original,
        m,
        n_bins + 3,
        (0, 2, *range(3, n_bins + 3)),
        lambda e: np.column_stack([e[:, 0], e[:, 2], e[:, 3:]]),
    )


def _pcd_data_line(data: bytes) -> int | None:
    for i, ln in enumerate(ref_lines(data)[0], start=1):
        if ln.strip(b" \t").startswith(b"DATA"):
            return i
    return None


def _check_pcd(
    result: Any, mutated: bytes, original: bytes, m: Mutation, folder: Path
) -> list[str]:
    problems = _finite(result)
    if problems:
        return problems
    k = _pcd_data_line(mutated)
    if k is None:
        return ["accepted a PCD without DATA"]
    return _match_rows(
        np.asarray(result), mutated, original, m, 3, (0, 1), lambda e: e[:, :2], first_line=k + 1
    )


def _check_csv(
    result: Any, mutated: bytes, original: bytes, m: Mutation, folder: Path
) -> list[str]:
    k, begin, end, _ = result
    got = np.column_stack([k, begin, end]).astype(np.float64)
    problems = _finite(got)
    if problems:
        return problems
    if np.any(np.diff(k) <= 0) or np.any(end <= begin):
        return ["keyframes out of order accepted"]
    return _match_rows(
        got, mutated, original, m, 3, (0, 1), lambda e: e, delimiter=",", first_line=2
    )


def _check_toml(
    result: Any, mutated: bytes, original: bytes, m: Mutation, folder: Path
) -> list[str]:
    """Every key of the mutated file that was accepted has exactly its value in the config."""
    try:
        data = tomllib.loads(mutated.decode("utf-8"))
    except (UnicodeDecodeError, tomllib.TOMLDecodeError):
        return ["accepted a file that is not UTF-8 TOML"]
    tables: dict[str, Any] = {}
    for name, table in data.items():
        if name == "mounting":
            tables.update({f"mounting.{k}": v for k, v in table.items()})
        else:
            tables[name] = table
    for table, values in tables.items():
        for key, value in values.items():
            target, unit = TOML_SCHEMA[table][key]
            obj: Any = result
            for part in target.split("."):
                obj = getattr(obj, part)
            want = value
            if unit == "deg":
                want = (
                    tuple(math.radians(v) for v in value)
                    if isinstance(value, list)
                    else math.radians(value)
                )
            if isinstance(want, list):
                want = tuple(want)
            if isinstance(obj, float | int) and not isinstance(obj, bool):
                if isinstance(want, bool) or not isinstance(want, int | float) or obj != want:
                    return [f"[{table}] {key} = {value!r} became {obj!r}"]
                if isinstance(obj, int) and isinstance(want, float) and want != int(want):
                    return [f"[{table}] {key} = {value!r} became {obj!r}"]
            elif obj != want:
                return [f"[{table}] {key} = {value!r} became {obj!r}"]
    for name in ("sonar", "noise", "gates"):
        for v in vars(getattr(result, name)).values():
            if isinstance(v, float) and not math.isfinite(v):
                return [f"a non-finite {name} setting accepted"]
    return []


def _check_truth(
    result: Any, mutated: bytes, original: bytes, m: Mutation, folder: Path
) -> list[str]:
    rows = np.asarray(result["body_poses"]["rows"], dtype=np.float64)
    return _finite(rows) or ([] if np.all(np.diff(rows[:, 0]) >= 0) else ["truth times go back"])


def _check_extractor_toml(
    result: Any, mutated: bytes, original: bytes, m: Mutation, folder: Path
) -> list[str]:
    for k, v in result.to_dict().items():
        if isinstance(v, float) and not math.isfinite(v):
            return [f"extractor {k} = {v} accepted"]
    return []


def check_dataset(ds: Dataset) -> list[str]:
    """The promises of an opened dataset (the readers' and the gates')."""
    out = []
    g = ds.config.gates
    arrays = {
        "dvl.t": ds.dvl.t,
        "dvl.v": ds.dvl.v_mps[ds.dvl.valid],
        "ahrs": ds.attitude.yaw_rad,
        "ahrs.rate": ds.attitude.yaw_rate_radps,
        "ahrs.t": ds.attitude.t,
    }
    if ds.gps is not None:
        arrays.update({"gps.t": ds.gps.t, "gps.en": ds.gps.en_m})
    for name, a in arrays.items():
        if not np.all(np.isfinite(a)):
            out.append(f"{name} not finite")
    if np.any(np.hypot(*ds.dvl.v_mps[ds.dvl.valid].T) > g.dvl_max_speed_mps):
        out.append("a valid DVL speed over the gate")
    for name, t in (
        ("dvl", ds.dvl.t),
        ("ahrs", ds.attitude.t),
        ("gps", ds.gps.t if ds.gps is not None else np.zeros(0)),
    ):
        if np.any(np.diff(t) <= 0):
            out.append(f"{name} times repeat or go back")
    if np.any(np.abs(ds.attitude.yaw_rate_radps) > math.radians(g.ahrs_max_rate_dps)):
        out.append("an AHRS rate over the gate")
    if ds.gps is not None and ds.gps.en_m.size and np.any(np.hypot(*ds.gps.en_m.T) > 1e6):
        out.append("a GPS fix 1000 km away (0/0?)")
    t0, t1 = ds.nav_span_s
    if not t1 >= t0:
        out.append("empty navigation span")
    if any(b.intensities.dtype != np.uint8 or not math.isfinite(b.t) for b in ds.beams):
        out.append("a beam that is not uint8 or at a finite time")
    return out


def _check_dataset(
    result: Any, mutated: bytes, original: bytes, m: Mutation, folder: Path
) -> list[str]:
    return check_dataset(result)


# --- settings on the command line ---------------------------------------------------------------

SET_FIELDS = [
    "extractor.min_votes",
    "extractor.rho_res_m",
    "extractor.theta_res_rad",
    "extractor.max_range_m",
    "extractor.sector_deg",
    "extractor.covariance_method",
    "extractor.vote_every_n_beams",
    "extractor.pose_uncertainty",
    "extractor.h_bearings",
    "ekf.association",
    "ekf.extent_margin_m",
    "ekf.association.gate_probability",
    "ekf.tentative_observations",
    "ekf.ahrs_period_s",
    "isam2.robust",
    "isam2.node_period_s",
    "isam2.extra_iterations",
    "isam2.max_candidates",
    "extractor.nope",
    "ekf",
    "nope.x",
    "ekf.association.nope",
]
SET_VALUES = TOKENS + [
    "true",
    "false",
    "none",
    "nn",
    "jcbb",
    "cauchy",
    "seed",
    "fit",
    "10",
    "0.01",
    "1e-9",
    "25",
]


def random_setting(rng: random.Random) -> str:
    return f"{rng.choice(SET_FIELDS)}={rng.choice(SET_VALUES)}"


def check_setting(spec: str) -> Outcome:
    """``--set SPEC`` for ``ekf`` and ``isam2``: a SettingError naming the key, or a config
    whose field holds exactly the typed value."""
    out = Outcome("--set", "accepted", f"set: {spec}")
    try:
        with _time_limit(10.0):
            settings = parse_settings([spec])
            backend = "isam2" if spec.startswith("isam2") else "ekf"
            check_settings(backend, settings)
    except _Hang:
        out.status = "hang"
        return out
    except SettingError as exc:
        out.status = "data_error"
        out.message = str(exc)
        key = spec.partition("=")[0].strip()
        if key not in str(exc) and "--set" not in str(exc):
            out.problems.append(f"message does not name {key!r}: {exc}")
        return out
    except Exception as exc:
        out.status = "foreign"
        out.message = f"{type(exc).__name__}: {exc}"
        out.problems.append(traceback.format_exc(limit=-3)[-600:])
        return out
    name, value = next(iter(settings.items()))
    scope, _, rest = name.partition(".")
    rest = "association.method" if rest == "association" else rest
    config = extractor_config("default") if scope == "extractor" else backend_config(scope)
    config = apply_overrides(config, {rest: value})
    got: Any = config
    for part in rest.split("."):
        got = getattr(got, part)
    same = got == value and type(got) is not bool or got is value
    if isinstance(got, float) and not math.isfinite(got) or not same:
        out.problems.append(f"{spec} gave {got!r}")
    return out


# --- the targets ----------------------------------------------------------------------------


@dataclass(frozen=True)
class Target:
    seed: str
    read: Callable[[Path], Any]
    check: Callable[[Any, bytes, bytes, Mutation, Path], list[str]]


TARGETS: dict[str, Target] = {
    "read_dvl": Target("dvl", read_dvl, _check_dvl),
    "read_mti": Target("mti", read_mti, _check_mti),
    "read_dgps": Target("dgps", read_dgps, _check_dgps),
    "read_is_timestamps": Target("stamps", read_is_timestamps, _check_stamps),
    "read_setup": Target("setup", read_setup, _check_setup),
    "read_is_log": Target("is_log", lambda p: read_is_log(p, n_bins=500), _check_is_log),
    "read_pcd_xy": Target("pcd", read_pcd_xy, _check_pcd),
    "read_keyframe_times": Target("csv", read_keyframe_times, _check_csv),
    "load_dataset_config": Target("toml", load_dataset_config, _check_toml),
    "read_truth": Target("truth", read_truth, _check_truth),
    "extract --config": Target(
        "extractor_toml", lambda p: extractor_config("default", p), _check_extractor_toml
    ),
    "open_dataset": Target("dataset", lambda p: open_dataset(_dataset_root(p)), _check_dataset),
}


def _dataset_root(primary: Path) -> Path:
    return primary.parent.parent if primary.parent.name == "logs" else primary.parent


def fuzz(
    seeds: dict[str, Seed],
    cases: int,
    work: Path,
    seed: int = 0,
    targets: list[str] | None = None,
    progress: Callable[[int], None] | None = None,
) -> list[Outcome]:
    """``cases`` seeded cases spread over the targets (and ``--set``); the outcomes.

    For ``open_dataset`` the mutated file is any file of the dataset. With the marina present,
    cases alternate between its slices and the simulated ones.
    """
    rng = random.Random(seed)
    names = targets or [*TARGETS, "--set"]
    outcomes = []
    for i in range(cases):
        name = names[i % len(names)]
        if name == "--set":
            outcomes.append(check_setting(random_setting(rng)))
        else:
            spec = TARGETS[name]
            s = seeds[spec.seed]
            if f"sim_{spec.seed}" in seeds and (i // len(names)) % 2:  # marina and simulated
                s = seeds[f"sim_{spec.seed}"]
            file = rng.choice(sorted(s.files)) if name == "open_dataset" else s.primary
            m = mutate(s.files[file], rng, file)
            if name == "open_dataset" and m.special is not None and rng.random() < 0.5:
                m = mutate(s.files[file], rng, file, special=False)
            outcomes.append(run_case(name, s, m, work))
        if progress is not None:
            progress(i)
    return outcomes


def summarise(outcomes: list[Outcome]) -> list[dict[str, Any]]:
    """One row per target: cases, accepted, data errors (with a line named), foreign
    exceptions, hangs, cases with a problem (wrong value, wrong file or line)."""
    rows = []
    for name in dict.fromkeys(o.target for o in outcomes):
        mine = [o for o in outcomes if o.target == name]
        rows.append(
            {
                "target": name,
                "cases": len(mine),
                "accepted": sum(o.status == "accepted" for o in mine),
                "data_error": sum(o.status == "data_error" for o in mine),
                "with_line": sum(o.named_line for o in mine),
                "foreign": sum(o.status == "foreign" for o in mine),
                "hang": sum(o.status == "hang" for o in mine),
                "problems": sum(bool(o.problems) for o in mine),
            }
        )
    return rows
