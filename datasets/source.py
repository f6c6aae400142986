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

import os
import warnings
from collections.abc import Sequence
from dataclasses import replace
from pathlib import Path

from sonarslam.datasets.config import MARINA_CONFIG, DatasetConfig, load_dataset_config
from sonarslam.datasets.dataset import (
    NEUTRAL_CALIBRATION,
    Dataset,
    check_overlap,
    dataset_span,
    mounting_tables,
    neutral_warning,
    read_truth,
    warn_assumed_mountings,
)
from sonarslam.datasets.errors import DataError, DataWarning
from sonarslam.datasets.gates import (
    SensorReport,
    gate_attitude,
    gate_beams,
    gate_dvl,
    gate_gps,
    navigation_span_s,
)
from sonarslam.datasets.islog import read_is_log
from sonarslam.datasets.keyframes import read_keyframes
from sonarslam.datasets.marina import read_dgps, read_dvl, read_is_timestamps, read_mti, read_setup
from sonarslam.datasets.navlog import NAV_LOG_KINDS, nav_log_kind
from sonarslam.datasets.ping360 import is_ping360_log, open_ping360
from sonarslam.datasets.records import BeamSeries
from sonarslam.datasets.rosbag import TOPIC_PRESETS, is_bag, open_bag
from sonarslam.datasets.toml import read_toml

__all__ = [
    "Dataset",
    "open_dataset",
    "resolve_source",
    "data_root",
    "read_truth",
    "is_marina",
    "NEUTRAL_CALIBRATION",
    "check_overlap",
    "check_toml_inputs",
]

ENV_VAR = "SONARSLAM_DATA"
#: The marina's logs are named ``_040825_1735_<sensor>.log`` (25 August 2004, 17:35): a
#: directory holding them (or the marina's keyframes) without a ``sonarslam.toml`` takes
#: :data:`MARINA_CONFIG`.
MARINA_LOG_PREFIX = "_040825_1735_"
NAMED_SOURCES = ("marina",)
#: The section of the docs that says how to get the marina and where to put it.
MARINA_DOCS = "docs/data.md#the-marina-getting-the-data"
#: Where the marina comes from and its layout, in one line (errors of a missing named source).
MARINA_LAYOUT_HINT = (
    "marina/logs/ (_040825_1735_*.log from the University of Girona's StPereDataset.zip, "
    "Ribas et al. 2008) and marina/keyframes/ (the thresholded scans, pclKeyFrame*.pcd with "
    f"keyFrameTimeStamps.csv); see {MARINA_DOCS}"
)


def data_root() -> Path | None:
    """``$SONARSLAM_DATA`` as a path, or None when unset."""
    value = os.environ.get(ENV_VAR)
    return Path(value) if value else None


def resolve_source(source: str | Path) -> Path:
    """A named source (``marina``) under ``$SONARSLAM_DATA``, a directory, a ROS bag or a Ping
    Viewer ``.bin`` log."""
    path = Path(source)
    kind = nav_log_kind(path) if path.is_file() else None
    if kind is not None:
        raise DataError(
            path,
            None,
            f"a navigation log ({NAV_LOG_KINDS[kind]}), not a sonar log: give it as --nav beside the"
            " Ping Viewer .bin (sonarslam info FILE says what it holds)",
        )
    if path.is_dir() or is_bag(path) or is_ping360_log(path):
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
    if not path.exists():
        raise DataError(
            path,
            None,
            "no such file or directory (a source is a directory, a ROS bag, a Ping Viewer .bin or"
            f" a named source: {', '.join(NAMED_SOURCES)})",
        )
    raise DataError(path, None, f"not a directory, nor a named source ({', '.join(NAMED_SOURCES)})")


def _find_one(root: Path, pattern: str, required: bool) -> Path | None:
    found = sorted(set(root.glob(pattern)) | set(root.glob(f"*/{pattern}")))
    if len(found) > 1:
        raise DataError(root, None, f"more than one {pattern}: {[str(f) for f in found]}")
    if not found and required:
        raise DataError(root, None, f"missing {pattern}")
    return found[0] if found else None


def open_dataset(
    source: str | Path,
    config_override: str | Path | None = None,
    topics_file: str | Path | None = None,
    nav: str | Path | Sequence[str | Path] | None = None,
    span_s: tuple[float, float] | None = None,
) -> Dataset:
    """Read a dataset directory, a ROS bag, a Ping Viewer log or a named source into a
    :class:`Dataset`.

    Parameters
    ----------
    source : str or Path
        A directory in the marina layout, a ROS 1 ``.bag``, a ROS 2 bag (directory or ``.mcap``;
        :func:`sonarslam.datasets.rosbag.open_bag`), a Ping Viewer ``.bin`` log
        (:func:`sonarslam.datasets.ping360.open_ping360`), or a named source (``"marina"``).
    config_override : str or Path, optional
        A ``sonarslam.toml``-format file whose keys replace those of the dataset's own
        configuration (its ``sonarslam.toml``, else the marina calibration); keys it leaves out
        keep the dataset's values. For trying another calibration without editing the data.
    topics_file : str or Path, optional
        A bag's roles (``[topics]``: ``sonar``, ``dvl``, ``imu``, ``gps``), for a bag or a
        ``.bin``'s navigation bag.
    nav : str or Path, or a sequence of them, optional
        A ``.bin``'s navigation (a ROS bag, a CSV, a BlueROV2's own logs:
        :mod:`sonarslam.datasets.navlog`), over its ``[ping360] nav``.
    span_s : (float, float), optional
        Only the part from ``T0`` to ``T1`` (s from the start of the navigation,
        :func:`sonarslam.datasets.dataset.dataset_span`; ``--span``).

    Raises
    ------
    DataError
        A missing required file or any bad input (see :mod:`sonarslam.datasets.logfile`), DVL and AHRS
        logs that do not overlap in time, a malformed ``truth.json``. Sensor faults that
        pass the readers are gated with warnings (:mod:`sonarslam.datasets.gates`).
    """
    dataset = _open(source, config_override, topics_file, nav)
    return dataset if span_s is None else dataset_span(dataset, span_s)


def _open(
    source: str | Path,
    config_override: str | Path | None,
    topics_file: str | Path | None,
    nav: str | Path | Sequence[str | Path] | None,
) -> Dataset:
    """:func:`open_dataset` of the whole source."""
    root = resolve_source(source)
    if is_ping360_log(root):
        check_toml_inputs(root, topics_file)
        return open_ping360(root, config_override, topics_file, nav)
    if nav is not None:
        first = nav if isinstance(nav, (str, Path)) else next(iter(nav), "--nav")
        raise DataError(Path(first), None, "--nav is for a Ping Viewer .bin log")
    if is_bag(root):
        check_toml_inputs(root, topics_file)
        return open_bag(root, config_override, topics_file)
    if topics_file is not None:
        raise DataError(
            Path(topics_file), None, "--topics is for ROS bags; the source is a directory"
        )
    config, calibration = _config(root, config_override)
    report = SensorReport()
    gates = config.gates
    dvl_path = _find_one(root, "*_DVL.log", required=True)
    mti_path = _find_one(root, "*_MTi.log", required=True)
    assert dvl_path is not None and mti_path is not None
    dvl = gate_dvl(read_dvl(dvl_path), gates, report, config.noise.dvl_sigma_mps)
    attitude = gate_attitude(read_mti(mti_path), gates, report)
    check_overlap(root, dvl, attitude)
    gps_path = _find_one(root, "*_DGPS.log", required=False)
    gps = gate_gps(read_dgps(gps_path), gates, report) if gps_path is not None else None
    beams, sonar_path = _beams(root, config)
    gate_beams(beams.t_s, gates, report, sonar_path, navigation_span_s(dvl, attitude))
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


def check_toml_inputs(root: Path, topics_file: str | Path | None) -> None:
    """Read the ``--topics`` file (unless a preset's name) and a bag's own ``sonarslam.toml`` as
    TOML before the readers take their ``[topics]``: a missing file or a syntax error is then a
    :class:`DataError` as ``--config``'s (``file not found``, the syntax error's line)."""
    if topics_file is not None and str(topics_file) not in TOPIC_PRESETS:
        read_toml(Path(topics_file))
    if is_bag(root):
        beside = (root if root.is_dir() else root.parent) / "sonarslam.toml"
        if beside.is_file():
            read_toml(beside)


def is_marina(root: Path) -> bool:
    """True for a directory of the marina: its own DVL log (:data:`MARINA_LOG_PREFIX`), or its
    thresholded keyframes (``keyFrameTimeStamps.csv``, a format only the marina has; the test
    suite's windows of the marina rename the logs and keep them)."""
    names = (f"{MARINA_LOG_PREFIX}DVL.log", "keyFrameTimeStamps.csv")
    return any((root / n).is_file() or any(root.glob(f"*/{n}")) for n in names)


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
            warnings.warn(neutral_warning(root), DataWarning, stacklevel=3)
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
    if calibration != NEUTRAL_CALIBRATION:  # a neutral run is said whole above
        warn_assumed_mountings(
            root, config, mounting_tables(toml) | mounting_tables(config_override)
        )
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
