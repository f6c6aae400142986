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
                            :mod:`datasets.config`; keys it leaves out take neutral
                            defaults); without it, the marina's calibration
``truth.json``              the simulator's ground truth (optional)
==========================  ===========================================================

``open_dataset("marina")`` finds ``$SONARSLAM_DATA/marina``.
"""

from __future__ import annotations

import heapq
import json
import os
from collections.abc import Iterator
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

from datasets.config import MARINA_CONFIG, DatasetConfig, load_dataset_config
from datasets.errors import DataError
from datasets.islog import read_is_log
from datasets.keyframes import read_keyframes
from datasets.marina import read_dgps, read_dvl, read_is_timestamps, read_mti, read_setup
from datasets.records import AttitudeSeries, DvlSeries, GpsSeries, Record
from sonar.beam import SonarBeam

__all__ = ["Dataset", "open_dataset", "resolve_source", "data_root"]

ENV_VAR = "SONARSLAM_DATA"
NAMED_SOURCES = ("marina",)


@dataclass(frozen=True, eq=False)
class Dataset:
    """All the logs of one run, read and checked."""

    name: str
    root: Path
    config: DatasetConfig
    beams: list[SonarBeam]
    dvl: DvlSeries
    attitude: AttitudeSeries
    gps: GpsSeries | None
    truth: dict[str, Any] | None = None

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

    def nav_beams(self) -> list[SonarBeam]:
        """The beams inside :attr:`nav_span_s` (the marina sonar starts ~183 s earlier)."""
        t0, t1 = self.nav_span_s
        return [b for b in self.beams if t0 <= b.t <= t1]

    def stream(
        self, t_start_s: float | None = None, t_end_s: float | None = None
    ) -> Iterator[Record]:
        """All records merged in time order (ties: AHRS, DVL, GPS, then sonar)."""
        lo = -float("inf") if t_start_s is None else t_start_s
        hi = float("inf") if t_end_s is None else t_end_s

        def keyed(records: list[Any], rank: int) -> Iterator[tuple[float, int, int, Any]]:
            for i, r in enumerate(records):
                if lo <= r.t <= hi:
                    yield (r.t, rank, i, r)

        streams = [
            keyed(self.attitude.records(), 0),
            keyed(self.dvl.records(), 1),
            keyed(self.gps.records() if self.gps is not None else [], 2),
            keyed(self.beams, 3),
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
                f"the named source {source!r} needs ${ENV_VAR} (e.g. ../shared/datasets)",
            )
        found = root / str(source)
        if not found.is_dir():
            raise DataError(found, None, f"no {source!r} dataset under ${ENV_VAR}={root}")
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
        A missing required file or any bad input (see :mod:`datasets.logfile`).
    """
    root = resolve_source(source)
    toml = _find_one(root, "sonarslam.toml", required=False)
    # a sonarslam.toml starts from neutral defaults (no clock offset, identity mountings): a
    # partial file must not inherit the marina's calibration silently
    config = load_dataset_config(toml) if toml else MARINA_CONFIG
    setup = _find_one(root, "*_SETUP.log", required=False)
    if setup is not None and toml is None:
        range_m, bin_m, step_rad = read_setup(setup)
        head = replace(
            config.sonar, n_bins=int(round(range_m / bin_m)), bin_size_m=bin_m, step_rad=step_rad
        )
        config = replace(config, sonar=head)
    if config_override is not None:
        config = load_dataset_config(config_override, base=config)

    dvl = read_dvl(_find_one(root, "*_DVL.log", required=True))  # type: ignore[arg-type]
    attitude = read_mti(_find_one(root, "*_MTi.log", required=True))  # type: ignore[arg-type]
    gps_path = _find_one(root, "*_DGPS.log", required=False)
    gps = read_dgps(gps_path) if gps_path is not None else None

    is_log = _find_one(root, "*_IS.log", required=False)
    if is_log is not None:
        beams = read_is_log(is_log, n_bins=config.sonar.n_bins)
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

    if config.sonar_time_offset_s:
        beams = [replace(b, t=b.t + config.sonar_time_offset_s) for b in beams]

    truth_path = _find_one(root, "truth.json", required=False)
    truth = json.loads(truth_path.read_text()) if truth_path is not None else None
    name = root.name
    return Dataset(
        name=name,
        root=root,
        config=config,
        beams=beams,
        dvl=dvl,
        attitude=attitude,
        gps=gps,
        truth=truth,
    )
