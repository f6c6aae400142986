"""The :class:`Dataset` of one run (however it was read), the DVL/AHRS overlap check and the
simulator's ``truth.json``; the readers are :mod:`sonarslam.datasets.source` (directories),
:mod:`sonarslam.datasets.arrays` (numpy arrays) and :mod:`sonarslam.datasets.rosbag` (ROS bags)."""

from __future__ import annotations

import heapq
import json
import tomllib
import warnings
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from sonarslam.datasets.config import DatasetConfig
from sonarslam.datasets.errors import DataError, DataWarning
from sonarslam.datasets.gates import SensorReport, navigation_span_s
from sonarslam.datasets.logfile import read_text
from sonarslam.datasets.records import (
    AttitudeSeries,
    BeamSeries,
    DvlSeries,
    GpsSeries,
    Record,
    SonarSegment,
    farthest_segment,
)

__all__ = [
    "Dataset",
    "NEUTRAL_CALIBRATION",
    "check_overlap",
    "neutral_warning",
    "read_truth",
    "dataset_span",
]

_NEUTRAL = "neutral: no sonarslam.toml, so identity mountings, no clock offset and default noise"
#: :attr:`Dataset.calibration` of a run that is not the marina and has no ``sonarslam.toml``.
NEUTRAL_CALIBRATION = (
    f"{_NEUTRAL} (write one: sonarslam calibrate SOURCE --write FOLDER/sonarslam.toml, FOLDER"
    " the source if a directory, else the one holding its file; docs/data.md)"
)


#: The sensors with a mounting in a ``sonarslam.toml`` (``[mounting.<sensor>]``).
MOUNTED_SENSORS = ("sonar", "dvl", "ahrs")


def mounting_tables(toml: str | Path | None) -> set[str]:
    """The sensors (``sonar``, ``dvl``, ``ahrs``) whose ``[mounting.<sensor>]`` table a
    ``sonarslam.toml``-format file has; none for a file that cannot be read
    (:func:`sonarslam.datasets.config.load_dataset_config` names its problem)."""
    if toml is None:
        return set()
    try:
        data = tomllib.loads(Path(toml).read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError):
        return set()
    mounting = data.get("mounting", {})
    return set(mounting) if isinstance(mounting, dict) else set()


def warn_assumed_mountings(source: Path, config: DatasetConfig, tables: set[str]) -> None:
    """A :class:`DataWarning` naming each sensor whose mounting nobody gave
    (:attr:`sonarslam.sonar.beam.Mounting.assumed`: the identity, left out or written down as
    an assumption), when the others have a source or a file's table (``tables``,
    :func:`mounting_tables`) writes the assumption down: one sensor forgotten among given ones
    is not a choice the user made, and a file that holds an assumption (``sonarslam calibrate
    --write`` of a run without mountings) must not silence it. A file without any mounting
    table leaves all three the identity without a word (the caller's neutral warning, or the
    user's choice)."""
    missing = [m for m in MOUNTED_SENSORS if getattr(config, f"{m}_mounting").assumed]
    if not missing or (len(missing) == len(MOUNTED_SENSORS) and not tables & set(missing)):
        return
    names = ", ".join(f"[mounting.{m}]" for m in missing)
    warnings.warn(
        f"{source}: the {', '.join(missing)} mounting(s) are the identity, assumed: nothing gave"
        f" them (write {names} with x_m, y_m, yaw_deg and a source in sonarslam.toml, zeros if"
        " that is the truth; a table whose source says 'assumed' is not a measurement). A"
        " DVL mounting turns dead reckoning's motion and the sonar yaw calibrated on it; an"
        " AHRS mounting turns the whole run about its start",
        DataWarning,
        stacklevel=3,
    )


def neutral_warning(source: Path) -> str:
    """The warning of a run of ``source`` on neutral settings (:data:`NEUTRAL_CALIBRATION`),
    naming the ``sonarslam.toml`` to write: inside a directory, beside a file."""
    toml = (source if source.is_dir() else source.parent) / "sonarslam.toml"
    return (
        f"{source}: {_NEUTRAL} (write one: sonarslam calibrate {source} --write {toml},"
        " docs/data.md)"
    )


@dataclass(frozen=True, eq=False)
class Dataset:
    """All the logs of one run, read and checked (:func:`sonarslam.datasets.source.open_dataset`).

    Attributes
    ----------
    name : str
        The run's name (its files' prefix).
    root : Path
        Its folder.
    config : DatasetConfig
        Its ``sonarslam.toml``: the sonar head (``config.sonar``), the mountings ``bTs`` of
        the sonar, DVL and AHRS, the sensors' noise.
    beams : BeamSeries
        Sonar beams in time order.
    dvl : DvlSeries
        DVL velocities in the DVL frame (m/s).
    attitude : AttitudeSeries
        AHRS headings (rad, CCW from East) and yaw rates.
    gps : GpsSeries or None
        GPS fixes in the readers' local East-North frame (m; origin at the first fix).
    truth : dict or None
        A simulated run's ``truth.json`` (:func:`read_truth`).
    report : SensorReport
        What the gates dropped and the sensors' gaps (:mod:`sonarslam.datasets.gates`).
    calibration : str
        Where ``config`` came from: the ``sonarslam.toml`` read, the marina's calibration, or
        :data:`NEUTRAL_CALIBRATION` (``run`` prints it, ``metrics.json`` records it).
    start_enu : (float, float, float) or None
        The start ``(x_m, y_m, yaw_rad)`` in the local East-North frame a user gave
        (``--start``; yaw NaN: none given, else checked against the AHRS's); None: the first
        GPS fix, or the origin without GPS (:func:`sonarslam.slam.run.sources.start_pose`).
    inputs : tuple of Path
        Files (or bag directories) read besides ``root`` and the ``sonarslam.toml`` and
        ``truth.json`` in or beside it: a ``--topics`` file, a Ping360 log's navigation
        (``metrics.json`` provenance digests them).
    segments : tuple of SonarSegment
        The stretches of the beams of one head setting (range, bin size, gain, sector), in
        time order, on the beams' clock: a Ping Viewer log's (``sonarslam info`` lists them);
        empty for a source of one setting.
    still : bool
        No navigation was given (a sonar log alone: a tank test, a head on a pier): the head
        is taken as still, at :attr:`start_enu` (the origin heading East when not given).
        ``dvl`` and ``attitude`` then hold two rows without bottom lock spanning the beams,
        no measurement: dead reckoning is the still pose
        (:func:`sonarslam.slam.run.sources.dead_reckoning_trajectory`), and nothing else runs.
    """

    name: str
    root: Path
    config: DatasetConfig
    beams: BeamSeries
    dvl: DvlSeries
    attitude: AttitudeSeries
    gps: GpsSeries | None
    truth: dict[str, Any] | None = None
    report: SensorReport = field(default_factory=SensorReport)
    calibration: str = ""
    start_enu: tuple[float, float, float] | None = None
    inputs: tuple[Path, ...] = ()
    segments: tuple[SonarSegment, ...] = ()
    still: bool = False

    @property
    def nav_span_s(self) -> tuple[float, float]:
        """Time span covered by both DVL and AHRS (Unix s): where the vehicle can be navigated
        (:func:`sonarslam.datasets.gates.navigation_span_s`)."""
        return navigation_span_s(self.dvl, self.attitude)

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
        """All records merged in time order (ties: AHRS, DVL, GPS, then sonar).

        Parameters
        ----------
        t_start_s, t_end_s : float, optional
            Keep the records with ``t_start_s <= t <= t_end_s`` (Unix s); default: all.

        Yields
        ------
        Record
            One sensor sample at a time, its time ``t`` never decreasing.
        """
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


def dataset_span(dataset: Dataset, span_rel_s: tuple[float, float]) -> Dataset:
    """The part of ``dataset`` from ``T0`` to ``T1`` of ``span_rel_s`` (s from the start of its
    navigation, :attr:`Dataset.nav_span_s`, as ``--loop`` and ``sonarslam info``'s segments
    count; a still head's, without navigation, from its first beam): its beams, DVL, AHRS and
    GPS rows in ``[start + T0, start + T1]``, its segments cut to it and the head theirs (``--span``: the farthest-reaching segment left,
    :func:`~sonarslam.datasets.records.farthest_segment`, sets the head's bin size, the most
    samples left its bins). A still head's (no navigation) two rows span the beams left. The
    gates' report stays the whole source's.

    Raises
    ------
    DataError
        A span that leaves fewer than two DVL or AHRS rows (no time to navigate), no beam, or
        GPS fixes none of which is inside its navigation (a run with GPS starts at the first
        one there), naming the span and the source's own.
    """
    t_nav0, t_nav1 = dataset.nav_span_s
    lo, hi = t_nav0 + span_rel_s[0], t_nav0 + span_rel_s[1]
    start = (
        "the first beam, the log having no navigation; the beams span"
        if dataset.still
        else "the start of the navigation, whose span is"
    )
    said = f"--span {span_rel_s[0]:g},{span_rel_s[1]:g} (s from {start} 0-{t_nav1 - t_nav0:.3f} s)"
    d, a, g = dataset.dvl, dataset.attitude, dataset.gps
    beams = dataset.beams.between(lo, hi)
    if not beams:
        raise DataError(dataset.root, None, f"{said} holds no sonar beam")
    if dataset.still:  # no navigation: its two rows span the beams
        t0, t1 = float(beams.t_s[0]), max(float(beams.t_s[-1]), float(beams.t_s[0]) + 1e-3)
        lo, hi = min(lo, t0), max(hi, t1)
        d = replace(d, t=np.array([t0, t1]))
        a = replace(a, t=np.array([t0, t1]))
    keep_d = (d.t >= lo) & (d.t <= hi)
    keep_a = (a.t >= lo) & (a.t <= hi)
    for name, keep in (("DVL", keep_d), ("AHRS", keep_a)):
        if np.count_nonzero(keep) < 2:
            raise DataError(
                dataset.root,
                None,
                f"{said} holds {np.count_nonzero(keep)} {name} row(s): a run needs a time span"
                " to navigate",
            )
    dvl = replace(
        d, t=d.t[keep_d], v_mps=d.v_mps[keep_d], valid=d.valid[keep_d],
        heading_rad=d.heading_rad[keep_d],
    )  # fmt: skip
    attitude = replace(
        a, t=a.t[keep_a], yaw_rad=a.yaw_rad[keep_a],
        yaw_rate_rad_per_s=a.yaw_rate_rad_per_s[keep_a],
    )  # fmt: skip
    gps = None
    if g is not None:
        keep_g = (g.t >= lo) & (g.t <= hi)
        fix = None if g.fix is None else g.fix[keep_g]
        gps = replace(g, t=g.t[keep_g], en_m=g.en_m[keep_g], fix=fix) if keep_g.any() else None
    if gps is not None and not dataset.still:
        # a run with GPS starts at its first fix inside the navigation (start_pose): fixes of
        # the span before the DVL and AHRS both log, or after, leave it none
        n0, n1 = navigation_span_s(dvl, attitude)
        if not np.any((gps.t >= n0) & (gps.t <= n1)):
            raise DataError(
                dataset.root,
                None,
                f"{said} holds no GPS fix inside its navigation (the DVL and AHRS both logging,"
                f" {n0 - t_nav0:.3f}-{n1 - t_nav0:.3f} s; its {gps.t.size} fix(es) fall outside):"
                " a run with GPS starts at its first fix there; give a longer span",
            )
    cut = [replace(s, t0_s=max(s.t0_s, lo), t1_s=min(s.t1_s, hi)) for s in dataset.segments]
    segments = tuple(
        replace(s, beams=len(beams.between(s.t0_s, s.t1_s))) for s in cut if s.t0_s <= s.t1_s
    )
    config = dataset.config
    if segments:
        n_bins = max(s.n_bins for s in segments)
        head = replace(
            config.sonar, n_bins=n_bins, bin_size_m=farthest_segment(segments).bin_size_m
        )
        own = beams.bin_size_m
        if own is not None and np.all(own == head.bin_size_m):
            own = None
        beams = BeamSeries(
            beams.t_s,
            beams.transducer_angle_rad,
            beams.intensities[:, :n_bins],
            beams.thresholded,
            own,
        )
        config = replace(config, sonar=head)
    return replace(
        dataset,
        config=config,
        beams=beams,
        dvl=dvl,
        attitude=attitude,
        gps=gps,
        segments=segments,
    )


#: DVL and AHRS whose overlap covers less than this share of their logs' span, or leaves out
#: more than :data:`MAX_LEFT_OUT_S` of it, give a run of that overlap only: a warning says so.
MIN_OVERLAP_SHARE = 0.5
MAX_LEFT_OUT_S = 60.0


def check_overlap(root: Path, dvl: DvlSeries, attitude: AttitudeSeries) -> None:
    """A log of one row (a span of 0 s), logs that do not overlap: :class:`DataError`; an
    overlap that leaves out more than a minute or more than half of their span: a
    :class:`DataWarning` (the run covers the overlap only)."""
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
    if whole - (t1 - t0) > MAX_LEFT_OUT_S or t1 - t0 < MIN_OVERLAP_SHARE * whole:
        warnings.warn(
            f"{root}: the DVL and AHRS overlap for {t1 - t0:.1f} s ({t0:.3f}-{t1:.3f} s) of"
            f" their {whole:.1f} s (it leaves out more than {MAX_LEFT_OUT_S:.0f} s or"
            f" {1 - MIN_OVERLAP_SHARE:.0%}): the run covers that overlap only",
            DataWarning,
            stacklevel=3,
        )


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
