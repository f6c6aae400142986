"""The fuzzer's oracles (``tests/fuzzing.py``): what an accepted result must be, per target."""

from __future__ import annotations

import math
import tomllib
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from sonarslam.datasets.config import _SCHEMA as TOML_SCHEMA  # what each key of the file sets
from sonarslam.datasets.ping360 import read_ping360_log
from sonarslam.datasets.source import Dataset
from sonarslam.features.geometry import wrap_angle
from tests.fuzz_inputs import Mutation, ref_lines, ref_rows

__all__ = [
    "check_dataset",
    "match_rows",
    "check_dvl",
    "check_mti",
    "check_dgps",
    "check_stamps",
    "check_setup",
    "check_is_log",
    "check_ping360",
    "check_pcd",
    "check_csv",
    "check_toml",
    "check_truth",
    "check_extractor_toml",
    "check_opened_dataset",
]

# --- oracles per target -----------------------------------------------------------------------


def _finite(*arrays: Any) -> list[str]:
    return [
        "returned a value that is not finite"
        for a in arrays
        if not np.all(np.isfinite(np.asarray(a, dtype=np.float64)))
    ][:1]


def match_rows(
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


def check_dvl(result: Any, mutated: bytes, original: bytes, m: Mutation, folder: Path) -> list[str]:
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

    return match_rows(got, mutated, original, m, 32, (0, 11, 12, 14, 22), conv)


def check_mti(result: Any, mutated: bytes, original: bytes, m: Mutation, folder: Path) -> list[str]:
    got = np.column_stack([result.t, result.yaw_rad, result.yaw_rate_rad_per_s])
    problems = _finite(got)
    if problems:
        return problems

    def conv(e: np.ndarray) -> np.ndarray:
        return np.column_stack([e[:, 0], _wrap(np.pi / 2 - np.deg2rad(e[:, 3])), -e[:, 6]])

    return match_rows(got, mutated, original, m, 10, (0, 3, 6), conv)


def check_dgps(
    result: Any, mutated: bytes, original: bytes, m: Mutation, folder: Path
) -> list[str]:
    problems = _finite(result.t, result.en_m)
    if problems:
        return problems
    got = np.column_stack([result.t, result.fix])

    def conv(e: np.ndarray) -> np.ndarray:
        zero = (e[:, 1] == 0) & (e[:, 2] == 0)
        return np.column_stack([e[:, 0], np.isin(e[:, 3], (1, 2, 3, 4, 5)) & ~zero])

    out = match_rows(got, mutated, original, m, 10, (0, 1, 2, 3), conv)
    ref = ref_rows(mutated, 10)
    for _, v in ref:
        for c in (1, 2):
            minutes = abs(v[c]) - 100 * math.floor(abs(v[c]) / 100)
            if minutes >= 60 and len(ref) == got.shape[0]:
                return out + ["accepted minutes >= 60"]
    return out


def check_stamps(
    result: Any, mutated: bytes, original: bytes, m: Mutation, folder: Path
) -> list[str]:
    got = np.asarray(result)[:, None]
    return _finite(got) or match_rows(got, mutated, original, m, 2, (0,), lambda e: e[:, :1])


def check_setup(
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


def check_is_log(
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
    return match_rows(
        got,
        mutated,
        original,
        m,
        n_bins + 3,
        (0, 2, *range(3, n_bins + 3)),
        lambda e: np.column_stack([e[:, 0], e[:, 2], e[:, 3:]]),
    )


def check_ping360(
    result: Any, mutated: bytes, original: bytes, m: Mutation, folder: Path
) -> list[str]:
    """A Ping Viewer log: every beam kept is one of the unmutated log's (its angle and
    samples), in time order; a log cut short keeps the uncut log's first beams exactly."""
    beams = result.beams
    problems = _finite(beams.t_s, beams.transducer_angle_rad, result.bin_size_m)
    if problems:
        return problems
    if len(beams) == 0:
        return ["no beams, no error"]
    if np.any(np.diff(beams.t_s) < 0) or np.any(beams.transducer_angle_rad >= 2 * math.pi):
        return ["beams out of time order, or an angle of a turn or more"]
    ref_path = folder / "reference" / m.file
    ref_path.parent.mkdir(exist_ok=True)
    ref_path.write_bytes(original)
    ref = read_ping360_log(ref_path).beams
    known = {
        (round(a * 200 / math.pi), row.tobytes())
        for a, row in zip(ref.transducer_angle_rad, ref.intensities, strict=True)
    }
    for a, row in zip(beams.transducer_angle_rad, beams.intensities, strict=True):
        if (round(a * 200 / math.pi), row.tobytes()) not in known:
            return ["a beam that is not in the log"]
    if m.kind == "cut":
        n = len(beams)
        if not (
            np.array_equal(beams.intensities, ref.intensities[:n])
            and np.array_equal(beams.t_s, ref.t_s[:n])
        ):
            return ["a log cut short: the beams kept are not the uncut log's first"]
    return []


def _pcd_data_line(data: bytes) -> int | None:
    for i, ln in enumerate(ref_lines(data)[0], start=1):
        if ln.strip(b" \t").startswith(b"DATA"):
            return i
    return None


def check_pcd(result: Any, mutated: bytes, original: bytes, m: Mutation, folder: Path) -> list[str]:
    problems = _finite(result)
    if problems:
        return problems
    k = _pcd_data_line(mutated)
    if k is None:
        return ["accepted a PCD without DATA"]
    return match_rows(
        np.asarray(result), mutated, original, m, 3, (0, 1), lambda e: e[:, :2], first_line=k + 1
    )


def check_csv(result: Any, mutated: bytes, original: bytes, m: Mutation, folder: Path) -> list[str]:
    k, begin, end, _ = result
    got = np.column_stack([k, begin, end]).astype(np.float64)
    problems = _finite(got)
    if problems:
        return problems
    if np.any(np.diff(k) <= 0) or np.any(end <= begin):
        return ["keyframes out of order accepted"]
    return match_rows(
        got, mutated, original, m, 3, (0, 1), lambda e: e, delimiter=",", first_line=2
    )


def check_toml(
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


def check_truth(
    result: Any, mutated: bytes, original: bytes, m: Mutation, folder: Path
) -> list[str]:
    rows = np.asarray(result["body_poses"]["rows"], dtype=np.float64)
    return _finite(rows) or ([] if np.all(np.diff(rows[:, 0]) >= 0) else ["truth times go back"])


def check_extractor_toml(
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
        "ahrs.rate": ds.attitude.yaw_rate_rad_per_s,
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
    if np.any(np.abs(ds.attitude.yaw_rate_rad_per_s) > math.radians(g.ahrs_max_rate_deg_per_s)):
        out.append("an AHRS rate over the gate")
    if ds.gps is not None and ds.gps.en_m.size and np.any(np.hypot(*ds.gps.en_m.T) > 1e6):
        out.append("a GPS fix 1000 km away (0/0?)")
    t0, t1 = ds.nav_span_s
    if not t1 >= t0:
        out.append("empty navigation span")
    if any(b.intensities.dtype != np.uint8 or not math.isfinite(b.t) for b in ds.beams):
        out.append("a beam that is not uint8 or at a finite time")
    return out


def check_opened_dataset(
    result: Any, mutated: bytes, original: bytes, m: Mutation, folder: Path
) -> list[str]:
    return check_dataset(result)
