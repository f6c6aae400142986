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
  rules of :mod:`sonarslam.datasets.logfile`) finds in the mutated text; for a file cut short, every
  value it kept equal to the uncut file's; for a dataset, the gates' promises (no DVL speed
  over the limit, no GPS fix at 0/0 or repeated, no unexplained AHRS jump...);
* ``data_error``: a :class:`sonarslam.datasets.errors.DataError` (or for settings a
  :class:`sonarslam.settings.SettingError`); the oracle checks that it names the mutated file
  and, when it names a line, that the line is one the mutation changed (or the data line
  after one: time going backwards is seen there);
* ``foreign``: any other exception (a bug); ``hang``: no answer within the time limit.
"""

from __future__ import annotations

import difflib
import math
import random
import shutil
import signal
import tempfile
import traceback
import warnings
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from sonarslam.datasets.config import load_dataset_config
from sonarslam.datasets.errors import DataError, DataWarning
from sonarslam.datasets.islog import read_is_log
from sonarslam.datasets.keyframes import read_keyframe_times, read_pcd_xy
from sonarslam.datasets.marina import read_dgps, read_dvl, read_is_timestamps, read_mti, read_setup
from sonarslam.datasets.ping360 import read_ping360_log
from sonarslam.datasets.rosbag import open_bag
from sonarslam.datasets.source import open_dataset, read_truth
from sonarslam.settings import SettingError
from sonarslam.slam.run.presets import (
    apply_overrides,
    backend_config,
    check_settings,
    extractor_config,
    parse_settings,
)
from tests.fuzz_inputs import (
    TOKENS,
    Mutation,
    Seed,
    build_seeds,
    mutate,
    ref_lines,
    write_case,
)
from tests.fuzz_oracles import (
    check_csv,
    check_dgps,
    check_dvl,
    check_extractor_toml,
    check_is_log,
    check_mti,
    check_opened_dataset,
    check_pcd,
    check_ping360,
    check_setup,
    check_stamps,
    check_toml,
    check_truth,
)

__all__ = [
    "Seed",
    "Outcome",
    "TARGETS",
    "build_seeds",
    "run_case",
    "fuzz",
    "summarise",
    "check_setting",
]

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
            if m.file.endswith(".json") and "trailing comma" in str(exc):
                ok.add(min(ok) - 1)  # Python 3.13's json names the comma before a removed value
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
    "read_dvl": Target("dvl", read_dvl, check_dvl),
    "read_mti": Target("mti", read_mti, check_mti),
    "read_dgps": Target("dgps", read_dgps, check_dgps),
    "read_is_timestamps": Target("stamps", read_is_timestamps, check_stamps),
    "read_setup": Target("setup", read_setup, check_setup),
    "read_is_log": Target("is_log", lambda p: read_is_log(p, n_bins=500), check_is_log),
    "read_pcd_xy": Target("pcd", read_pcd_xy, check_pcd),
    "read_ping360_log": Target("ping360", read_ping360_log, check_ping360),
    "read_keyframe_times": Target("csv", read_keyframe_times, check_csv),
    "load_dataset_config": Target("toml", load_dataset_config, check_toml),
    "read_truth": Target("truth", read_truth, check_truth),
    "extract --config": Target(
        "extractor_toml", lambda p: extractor_config("default", p), check_extractor_toml
    ),
    "open_dataset": Target(
        "dataset", lambda p: open_dataset(_dataset_root(p)), check_opened_dataset
    ),
    **{
        f"open_bag {kind}": Target(
            f"bag_{kind}", lambda p: open_bag(_bag_root(p)), check_opened_dataset
        )
        for kind in ("ros1", "mcap", "sqlite3")
    },
}


def _bag_root(primary: Path) -> Path:
    """The bag a seed's file belongs to: a ``.bag`` itself, else its ROS 2 bag directory."""
    return primary if primary.suffix == ".bag" else primary.parent


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
