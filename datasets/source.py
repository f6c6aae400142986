"""A dataset directory in the marina layout, and the merged time-ordered record stream.

A directory (searched to two levels deep) holds, by file-name suffix:

==========================  ===========================================================
``*_DVL.log``               DVL (required)
``*_MTi.log``               AHRS (required)
``*_DGPS.log``              GPS (optional: ground truth only)
``*_IS.log``                raw sonar beams; or, without it,
``keyFrameTimeStamps.csv``  + ``pclKeyFrame*.pcd`` + ``*_IS_timestamps.log`` (marina keyframes)
``*_SETUP.log``             ``range_m bin_size_m step_rad`` of the head (optional)
``sonarslam.toml``          sonar settings, sensor mountings, noise (optional, see
                            :mod:`sonarslam.datasets.config`; keys it leaves out take neutral
                            defaults); without it, the marina's calibration for the marina's
                            own logs (``_040825_1735_*``) and neutral settings for any other
                            run, said by a warning and :attr:`Dataset.calibration`
``truth.json``              the simulator's ground truth (optional)
==========================  ===========================================================

``open_dataset("marina")`` finds ``$SONARSLAM_DATA/marina``.
"""

from __future__ import annotations

import heapq
import json
import os
import warnings
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from sonarslam.datasets.config import MARINA_CONFIG, DatasetConfig, load_dataset_config
from sonarslam.datasets.errors import DataError, DataWarning
from sonarslam.datasets.gates import SensorReport, gate_attitude, gate_beams, gate_dvl, gate_gps
from sonarslam.datasets.islog import read_is_log
from sonarslam.datasets.keyframes import read_keyframes
from sonarslam.datasets.logfile import read_text
from sonarslam.datasets.marina import read_dgps, read_dvl, read_is_timestamps, read_mti, read_setup
from sonarslam.datasets.records import AttitudeSeries, BeamSeries, DvlSeries, GpsSeries, Record

__all__ = [
    "Dataset",
    "open_dataset",
    "resolve_source",
    "data_root",
    "read_truth",
    "is_marina",
    "NEUTRAL_CALIBRATION",
]

ENV_VAR = "SONARSLAM_DATA"
#: The marina's logs are named ``_040825_1735_<sensor>.log`` (25 August 2004, 17:35): a
#: directory holding them without a ``sonarslam.toml`` takes :data:`MARINA_CONFIG`.
MARINA_LOG_PREFIX = "_040825_1735_"
#: :attr:`Dataset.calibration` of a run that is not the marina and has no ``sonarslam.toml``.
NEUTRAL_CALIBRATION = (
    "neutral: no sonarslam.toml, so identity mountings, no clock offset and default noise"
    " (write one: sonarslam calibrate SOURCE --write SOURCE/sonarslam.toml, docs/data.md)"
)
NAMED_SOURCES = ("marina",)
#: Where the marina comes from and its layout, in one line (errors of a missing named source).
MARINA_LAYOUT_HINT = (
    "marina/logs/ (_040825_1735_*.log from the University of Girona's StPereDataset.zip, "
    "Ribas et al. 2008) and marina/keyframes/ (the thresholded scans, pclKeyFrame*.pcd with "
    "keyFrameTimeStamps.csv); see the README's 'Getting the data'"
)


@dataclass(frozen=True, eq=False)
class Dataset:
    """All the logs of one run, read and checked; ``report`` counts what the gates dropped and
    lists the sensors' gaps (:mod:`sonarslam.datasets.gates`)."""

    name: str
    root: Path
    config: DatasetConfig
    beams: BeamSeries
    dvl: DvlSeries
    attitude: AttitudeSeries
    gps: GpsSeries | None
    truth: dict[str, Any] | None = None
    report: SensorReport = field(default_factory=SensorReport)
    #: Where :attr:`config` came from: the ``sonarslam.toml`` read, the marina's calibration,
    #: or :data:`NEUTRAL_CALIBRATION` (``run`` prints it, ``metrics.json`` records it).
    calibration: str = ""
    #: The start position ``(x_m, y_m, yaw_rad)`` in the local East-North frame a user gave
    #: (``--start``; yaw NaN: none given, else checked against the AHRS's); None: the first GPS
    #: fix, or the origin without GPS (see :func:`sonarslam.slam.run.sources.start_pose`).
    start_enu: tuple[float, float, float] | None = None

    @property
    def nav_span_s(self) -> tuple[float, float]:
        """Time span covered by both DVL and AHRS (Unix s): where the vehicle can be navigated."""
        return (
            max(float(self.dvl.t[0]), float(self.attitude.t[0])),
            min(float(self.dvl.t[-1]), float(self.attitude.t[-1])),
        )

    @property
    def sonar_span_s(self) -> tuple[float, float] | None:
        """First and last sonar beam inside :attr:`nav_span_s` (Unix s), None without beams
        there: where line features can correct the navigation."""
        beams = self.nav_beams()
        return (float(beams[0].t), float(beams[-1].t)) if beams else None

    def nav_beams(self) -> BeamSeries:
        """The beams inside :attr:`nav_span_s` (the marina sonar starts ~183 s earlier)."""
        return self.beams.between(*self.nav_span_s)

    def stream(
        self, t_start_s: float | None = None, t_end_s: float | None = None
    ) -> Iterator[Record]:
        """All records merged in time order (ties: AHRS, DVL, GPS, then sonar)."""
        lo = -float("inf") if t_start_s is None else t_start_s
        hi = float("inf") if t_end_s is None else t_end_s

        def keyed(records: Sequence[Any], rank: int) -> Iterator[tuple[float, int, int, Any]]:
            for i, r in enumerate(records):
                if lo <= r.t <= hi:
                    yield (r.t, rank, i, r)

        streams = [
            keyed(self.attitude.records(), 0),
            keyed(self.dvl.records(), 1),
            keyed(self.gps.records() if self.gps is not None else [], 2),
            keyed(self.beams.between(lo, hi), 3),
        ]
        for item in heapq.merge(*streams):
            yield item[3]


def data_root() -> Path | None:
    """``$SONARSLAM_DATA`` as a path, or None when unset."""
    value = os.environ.get(ENV_VAR)
    return Path(value) if value else None


def resolve_source(source: str | Path) -> Path:
    """A named source (``marina``) under ``$SONARSLAM_DATA``, or a directory path."""
    path = Path(source)
    if path.is_dir():
        return path
    if str(source) in NAMED_SOURCES:
        root = data_root()
        if root is None:
            raise DataError(
                path,
                None,
                f"the named source {source!r} needs ${ENV_VAR}: the folder that holds "
                f"{MARINA_LAYOUT_HINT}",
            )
        found = root / str(source)
        if not found.is_dir():
            raise DataError(
                found,
                None,
                f"no {source!r} dataset under ${ENV_VAR}={root}: it must hold {MARINA_LAYOUT_HINT}",
            )
        return found
    raise DataError(path, None, f"not a directory, nor a named source ({', '.join(NAMED_SOURCES)})")


def _find_one(root: Path, pattern: str, required: bool) -> Path | None:
    found = sorted(set(root.glob(pattern)) | set(root.glob(f"*/{pattern}")))
    if len(found) > 1:
        raise DataError(root, None, f"more than one {pattern}: {[str(f) for f in found]}")
    if not found and required:
        raise DataError(root, None, f"missing {pattern}")
    return found[0] if found else None


def open_dataset(source: str | Path, config_override: str | Path | None = None) -> Dataset:
    """Read a dataset directory (or a named source) into a :class:`Dataset`.

    Parameters
    ----------
    source : str or Path
        A directory in the marina layout, or a named source (``"marina"``).
    config_override : str or Path, optional
        A ``sonarslam.toml``-format file whose keys replace those of the dataset's own
        configuration (its ``sonarslam.toml``, else the marina calibration); keys it leaves out
        keep the dataset's values. For trying another calibration without editing the data.

    Raises
    ------
    DataError
        A missing required file or any bad input (see :mod:`sonarslam.datasets.logfile`), DVL and AHRS
        logs that do not overlap in time, a malformed ``truth.json``. Sensor faults that
        pass the readers are gated with warnings (:mod:`sonarslam.datasets.gates`).
    """
    root = resolve_source(source)
    config, calibration = _config(root, config_override)
    report = SensorReport()
    gates = config.gates
    dvl_path = _find_one(root, "*_DVL.log", required=True)
    mti_path = _find_one(root, "*_MTi.log", required=True)
    assert dvl_path is not None and mti_path is not None
    dvl = gate_dvl(read_dvl(dvl_path), gates, report)
    attitude = gate_attitude(read_mti(mti_path), gates, report)
    check_overlap(root, dvl, attitude)
    gps_path = _find_one(root, "*_DGPS.log", required=False)
    gps = gate_gps(read_dgps(gps_path), gates, report) if gps_path is not None else None
    beams, sonar_path = _beams(root, config)
    gate_beams(beams.t_s, gates, report, sonar_path)
    truth_path = _find_one(root, "truth.json", required=False)
    return Dataset(
        name=root.name,
        root=root,
        config=config,
        beams=beams,
        dvl=dvl,
        attitude=attitude,
        gps=gps,
        truth=read_truth(truth_path) if truth_path is not None else None,
        report=report,
        calibration=calibration,
    )


#: DVL and AHRS that overlap for less than this share of their logs' span, or for less than
#: :data:`MIN_OVERLAP_S`, give a run of that overlap only: a warning says so.
MIN_OVERLAP_SHARE = 0.5
MIN_OVERLAP_S = 60.0


def check_overlap(root: Path, dvl: DvlSeries, attitude: AttitudeSeries) -> None:
    """A log of one row (a span of 0 s), logs that do not overlap: :class:`DataError`; an
    overlap shorter than a minute or than half their span: a :class:`DataWarning`."""
    for series, name in ((dvl, "DVL"), (attitude, "AHRS")):
        if series.t.size < 2 or series.t[-1] <= series.t[0]:
            raise DataError(
                series.path or root,
                None,
                f"the {name} log has {series.t.size} row(s) spanning"
                f" {series.t[-1] - series.t[0]:.3f} s: a run needs a time span to navigate",
            )
    t0, t1 = max(dvl.t[0], attitude.t[0]), min(dvl.t[-1], attitude.t[-1])
    if t1 <= t0:
        raise DataError(
            root,
            None,
            f"the DVL ({dvl.t[0]:.3f}-{dvl.t[-1]:.3f} s) and AHRS ({attitude.t[0]:.3f}-"
            f"{attitude.t[-1]:.3f} s) logs do not overlap in time",
        )
    whole = max(dvl.t[-1], attitude.t[-1]) - min(dvl.t[0], attitude.t[0])
    if t1 - t0 < MIN_OVERLAP_S or t1 - t0 < MIN_OVERLAP_SHARE * whole:
        warnings.warn(
            f"{root}: the DVL and AHRS overlap for {t1 - t0:.1f} s ({t0:.3f}-{t1:.3f} s) of"
            f" their {whole:.1f} s (less than {MIN_OVERLAP_S:.0f} s or"
            f" {MIN_OVERLAP_SHARE:.0%}): the run covers that overlap only",
            DataWarning,
            stacklevel=3,
        )


def is_marina(root: Path) -> bool:
    """True for a directory holding the marina's own DVL log (:data:`MARINA_LOG_PREFIX`)."""
    name = f"{MARINA_LOG_PREFIX}DVL.log"
    return (root / name).is_file() or any(root.glob(f"*/{name}"))


def _config(root: Path, config_override: str | Path | None) -> tuple[DatasetConfig, str]:
    """The dataset's configuration and where it came from: its ``sonarslam.toml``; else the
    marina's calibration for the marina's logs, neutral settings for any other (a
    :class:`DataWarning` says so); with the head of ``*_SETUP.log``; then the override's keys."""
    toml = _find_one(root, "sonarslam.toml", required=False)
    # a sonarslam.toml starts from neutral defaults (no clock offset, identity mountings): a
    # partial file must not inherit the marina's calibration silently, nor may another run
    if toml is not None:
        config, calibration = load_dataset_config(toml), str(toml)
    elif is_marina(root):
        config, calibration = MARINA_CONFIG, "marina calibration (MARINA_CONFIG)"
    else:
        config, calibration = DatasetConfig(), NEUTRAL_CALIBRATION
        if config_override is None:
            warnings.warn(f"{root}: {NEUTRAL_CALIBRATION}", DataWarning, stacklevel=3)
    setup = _find_one(root, "*_SETUP.log", required=False)
    if setup is not None and toml is None:
        range_m, bin_m, step_rad = read_setup(setup)
        head = replace(
            config.sonar, n_bins=int(round(range_m / bin_m)), bin_size_m=bin_m, step_rad=step_rad
        )
        config = replace(config, sonar=head)
    if config_override is not None:
        config = load_dataset_config(config_override, base=config)
        calibration = f"{calibration}; over it {config_override}"
    return config, calibration


def _beams(root: Path, config: DatasetConfig) -> tuple[BeamSeries, Path]:
    """The sonar beams on the navigation clock, from a raw ``*_IS.log`` or the marina
    keyframes; and the file that gave their times."""
    is_log = _find_one(root, "*_IS.log", required=False)
    if is_log is not None:
        beams = read_is_log(is_log, n_bins=config.sonar.n_bins)
        source = is_log
    else:
        times_csv = _find_one(root, "keyFrameTimeStamps.csv", required=False)
        stamps = _find_one(root, "*_IS_timestamps.log", required=False)
        if times_csv is None or stamps is None:
            raise DataError(
                root,
                None,
                "no sonar: need *_IS.log, or keyFrameTimeStamps.csv with pclKeyFrame*.pcd"
                " and *_IS_timestamps.log",
            )
        beams = read_keyframes(
            times_csv.parent,
            read_is_timestamps(stamps),
            config.sonar,
            config.keyframe_scan_direction,
        )
        source = stamps
    if config.sonar_time_offset_s:
        beams = beams.shifted(config.sonar_time_offset_s)
    return beams, source


def _reject_constant(name: str) -> Any:
    raise ValueError(f"{name} is not a number in strict JSON")


def _finite_array(path: Path, data: Any, key: str, shape: tuple[int | None, ...]) -> None:
    """DataError unless ``data`` is an array of finite numbers of ``shape`` (None: any)."""
    try:
        a = np.asarray(data, dtype=np.float64)
    except (ValueError, TypeError, OverflowError):
        raise DataError(path, None, f"{key} is not an array of numbers") from None
    if a.ndim != len(shape) or any(
        n is not None and n != m for n, m in zip(shape, a.shape, strict=True)
    ):
        raise DataError(path, None, f"{key} must have shape {shape}, got {a.shape}")
    if not np.all(np.isfinite(a)):
        raise DataError(path, None, f"{key} holds a value that is not a finite number")


def read_truth(path: str | Path) -> dict[str, Any]:
    """``truth.json`` of a simulated run (UTF-8, strict JSON: no NaN or Infinity), with the
    parts the evaluation uses checked: ``body_poses.rows`` (N, 4) finite with non-decreasing
    times, ``first_fix_enu_m`` (2,) and ``walls_m`` (W, 2, 2) when present."""
    p = Path(path)
    text = read_text(p, "utf-8")
    try:
        data = json.loads(text, parse_constant=_reject_constant)
    except json.JSONDecodeError as exc:
        raise DataError(p, exc.lineno, f"not JSON: {exc.msg}") from None
    except (ValueError, RecursionError) as exc:
        raise DataError(p, None, f"not JSON: {exc}") from None
    if not isinstance(data, dict):
        raise DataError(p, None, "must be a JSON object")
    poses = data.get("body_poses")
    if not isinstance(poses, dict) or "rows" not in poses:
        raise DataError(p, None, "body_poses.rows missing")
    _finite_array(p, poses["rows"], "body_poses.rows", (None, 4))
    t = np.asarray(poses["rows"], dtype=np.float64)[:, 0]
    if t.size == 0 or np.any(np.diff(t) < 0):
        raise DataError(p, None, "body_poses.rows: no rows, or times going backwards")
    if "first_fix_enu_m" in data:
        _finite_array(p, data["first_fix_enu_m"], "first_fix_enu_m", (2,))
    if "walls_m" in data:
        _finite_array(p, data["walls_m"], "walls_m", (None, 2, 2))
    return data
