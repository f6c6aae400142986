"""Sonar settings and sensor mountings of a dataset, from an optional ``sonarslam.toml``.

A ``sonarslam.toml`` beside the logs overrides any of these keys (angles in degrees in the file,
radians in the objects)::

    [sonar]
    n_bins = 500            # bins per beam
    bin_size_m = 0.1        # range step (m); bin i (0-based) is at (i + 1) * bin_size_m
    step_deg = 1.8          # mechanical step between beams (deg)
    beam_width_deg = 3.0    # horizontal beam width alpha (deg)
    angle_sense = -1        # -1: logged transducer angle grows clockwise seen from above
    time_offset_s = 0.75    # added to the sonar's log times to put them on the navigation clock
    range_offset_m = 0.0    # the kept echo's range minus the wall's (m): subtracted from bin ranges

    [mounting.sonar]        # sonar head in the body frame (x forward, y left)
    x_m = 0.0
    y_m = 0.0
    yaw_deg = 154.75        # bearing in body = yaw + angle_sense * transducer angle
    source = "..."

    [mounting.dvl]          # DVL frame in the body frame
    yaw_deg = -90.0
    source = "..."

    [mounting.ahrs]         # AHRS frame in the body frame: body yaw = AHRS yaw - yaw
    yaw_deg = -114.5
    source = "..."

    [keyframes]             # only for datasets of keyframes (thresholded PCD scans)
    scan_direction = -1     # -1: the head turns toward decreasing angle (measured, see
                            # datasets/keyframes.py); +1: as the marina README says

    [noise]                 # 1-sigma sensor noise, every estimator's (NoiseConfig)
    dvl_sigma_mps = 0.05
    ahrs_sigma_deg = 2.0    # an AHRS heading, bias included (dead reckoning, GPS + AHRS)
    gps_sigma_m = 1.0
    dvl_max_gap_s = 10.0    # a DVL dropout longer than this inflates the velocity noise ...
    dvl_gap_sigma_mps = 0.3 # ... to this
    dvl_scatter_window_s = 60.0     # the DVL's own scatter over this window (0: off) ...
    dvl_nominal_scatter_mps = 0.2   # ... beyond its usual scatter is white noise added to
                            # dvl_sigma_mps (sonarslam info prints the scatter's quantiles)
    ahrs_gap_yaw_rate_sigma_deg_per_s = 1.0  # the unmeasured yaw rate in an AHRS gap
    ahrs_white_sigma_deg = 1.0      # the back ends' AHRS model: white noise ...
    ahrs_bias_sigma_deg = 2.0       # ... and a bias of this prior sigma ...
    ahrs_bias_walk_deg_per_sqrt_s = 0.0  # ... walking at this (0: a constant bias)
    gyro_sigma_rad_per_s = 0.005    # the back ends' heading process noise
    dvl_scale_sigma = 0.0   # 1-sigma of the DVL's scale-factor error (0: none)
    line_sigma_rho_m = 0.0  # a line's systematic error, added to every line's covariance
    line_sigma_theta_deg = 0.0      # (sonarslam calibrate --line-noise, GPS-free)

    [motion]
    yaw_rate_source = "heading"  # what turns the heading between AHRS samples: "gyro" (the
                            # logged rate) or "heading" (the AHRS heading's own change)
    ahrs_deviation_deg = [-2.01, 2.57]  # the AHRS yaw errs by B sin(yaw) + C cos(yaw) (deg):
                            # taken off (sonarslam calibrate --ahrs-deviation)

    [gates]                 # plausibility of the sensors' samples (datasets/gates.py)
    dvl_max_speed_mps = 3.0 # a faster DVL velocity is a spike: the row counts as no lock
    dvl_spike_sigmas = 12.0 # a velocity this many DVL scatters off both neighbours: a spike
    ahrs_max_jump_deg = 10.0      # a heading change the gyro does not explain by more ...
    ahrs_jump_drift_deg_per_s = 1.0     # ... (plus this per second since the last good sample)
    ahrs_max_rate_deg_per_s = 600.0     # a faster gyro rate is a spike: the sample is dropped
    gps_max_jump_m = 20.0   # a fix this far (plus dvl_max_speed_mps per s) from its
                            # neighbours' median is an outlier, dropped from the evaluation
    gap_periods = 5.0       # a sensor gap: no sample for this many of its median periods,
    min_gap_s = 1.0         # and at least this long

Every value is checked against the field it sets (type, finite, range: :mod:`sonarslam.settings`);
a wrong one is a ``DataError`` naming the file and the key. Keys a file leaves out take the
neutral defaults of :class:`DatasetConfig` (no clock offset,
identity mountings); the simulator writes every key. Without a file, a dataset gets the marina's
calibration (``MARINA_CONFIG``; docs/research/calibration.md says how each number was found and
whether GPS was used).
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import Any

import tomli_w

from sonarslam.datasets.errors import DataError
from sonarslam.datasets.toml import read_toml, toml_line
from sonarslam.settings import (
    SettingError,
    bounded,
    check_fields,
    coerce,
    field_types,
    one_of,
    replace_checked,
)
from sonarslam.sonar.beam import Mounting, SonarHead

__all__ = [
    "NoiseConfig",
    "GateConfig",
    "DatasetConfig",
    "MARINA_CONFIG",
    "RENAMED_KEYS",
    "load_dataset_config",
    "dump_dataset_config",
    "config_tables",
]


#: The DVL scale error's prior sigma stays below this (the back ends' ``1 + k`` must stay
#: positive well inside 3 sigma): one range, for the file and the back ends alike.
DVL_SCALE_SIGMA_MAX = 0.5


@dataclass(frozen=True)
class NoiseConfig:
    """1-sigma noise of the navigation sensors (the ``[noise]`` table): the one place every
    estimator takes its sensor noise from (dead reckoning and the motion model through
    :class:`sonarslam.slam.model.noise.MotionNoise`, the EKF and the factor graph through
    :class:`sonarslam.slam.backends.base.BackendConfig`'s ``noise``), and the extractor its
    lines' systematic error.

    The AHRS heading's error is modelled two ways: dead reckoning and the GPS + AHRS pose
    source take it as one white sigma (``ahrs_sigma_deg``, bias and all); the closed-loop
    back ends split it into white noise (``ahrs_white_sigma_deg``) and a bias they estimate
    (``ahrs_bias_sigma_deg``, walking at ``ahrs_bias_walk_deg_per_sqrt_s``).

    Attributes
    ----------
    dvl_sigma_mps : float
        A valid DVL velocity, per axis (m/s).
    ahrs_sigma_deg : float
        An AHRS heading, bias included, for dead reckoning and the GPS + AHRS poses (deg).
    gps_sigma_m : float
        A GPS fix, per axis (m).
    dvl_max_gap_s : float
        A DVL dropout up to this long holds the last valid velocity; longer, the velocity is
        taken as zero with ``dvl_gap_sigma_mps`` (s).
    dvl_gap_sigma_mps : float
        Velocity 1-sigma added during a dropout, growing linearly to this at
        ``dvl_max_gap_s`` (m/s).
    dvl_scatter_window_s : float
        Window of the DVL's own scatter (:func:`sonarslam.slam.model.noise.dvl_scatter`, s);
        0 turns the excess-scatter noise off.
    dvl_nominal_scatter_mps : float
        The DVL's usual scatter (m/s): its excess over this is white velocity noise added to
        ``dvl_sigma_mps`` (:func:`sonarslam.slam.model.noise.dvl_sample_sigma`).
    ahrs_gap_yaw_rate_sigma_deg_per_s : float
        The vehicle's yaw rate nobody measures while the AHRS is silent (deg/s): the heading
        variance grows with it over an AHRS gap.
    ahrs_white_sigma_deg : float
        The back ends' white noise of one AHRS heading (deg).
    ahrs_bias_sigma_deg : float
        The back ends' prior 1-sigma of the AHRS heading bias ``b`` (deg): the AHRS measures
        ``yaw + b``.
    ahrs_bias_walk_deg_per_sqrt_s : float
        The bias's random walk: ``b`` drifts by ``N(0, walk^2 dt)`` over ``dt``
        (deg/sqrt(s)); 0: a constant bias.
    gyro_sigma_rad_per_s : float
        The back ends' heading process noise, as a yaw-rate noise (rad/s), added as
        ``(dt sigma)^2`` per motion step.
    dvl_scale_sigma : float
        Prior 1-sigma of the DVL's scale-factor error ``k`` (a ratio; the vehicle moves along
        ``(1 + k) R v_b``); 0: none, not estimated.
    line_sigma_rho_m, line_sigma_theta_deg : float
        A line's systematic error (m, deg), added to every line's covariance by the extractor
        (``ExtractorConfig.line_sigma_rho_m`` and ``line_sigma_theta_rad``).
    """

    dvl_sigma_mps: float = bounded(0.05, 0.0, 10.0, low_open=True)
    ahrs_sigma_deg: float = bounded(2.0, 0.0, 180.0, low_open=True)
    gps_sigma_m: float = bounded(1.0, 0.0, 1e4, low_open=True)
    dvl_max_gap_s: float = bounded(10.0, 0.0, 3600.0, low_open=True)
    dvl_gap_sigma_mps: float = bounded(0.3, 0.0, 10.0)
    dvl_scatter_window_s: float = bounded(0.0, 0.0, 3600.0)
    dvl_nominal_scatter_mps: float = bounded(0.0, 0.0, 10.0)
    ahrs_gap_yaw_rate_sigma_deg_per_s: float = bounded(1.0, 0.0, 360.0)
    ahrs_white_sigma_deg: float = bounded(1.0, 1e-3, 90.0)
    ahrs_bias_sigma_deg: float = bounded(2.0, 1e-3, 90.0)
    ahrs_bias_walk_deg_per_sqrt_s: float = bounded(0.0, 0.0, 10.0)
    gyro_sigma_rad_per_s: float = bounded(0.005, 1e-5, 1.0)
    dvl_scale_sigma: float = bounded(0.0, 0.0, DVL_SCALE_SIGMA_MAX, high_open=True)
    line_sigma_rho_m: float = bounded(0.0, 0.0, 100.0)
    line_sigma_theta_deg: float = bounded(0.0, 0.0, 90.0)

    def __post_init__(self) -> None:
        check_fields(self)


@dataclass(frozen=True)
class GateConfig:
    """Plausibility gates of the sensors' samples (:mod:`sonarslam.datasets.gates`).

    Attributes
    ----------
    dvl_max_speed_mps : float
        A DVL bottom velocity faster than this (m/s, horizontal) is a spike: the row is taken
        as one without bottom lock (the motion model holds the last good velocity).
    dvl_spike_sigmas : float
        A valid DVL velocity farther than this many times the DVL's scatter from both its
        valid neighbours' (the run's own about the row: the median of 61 successive
        differences, at least ``[noise] dvl_sigma_mps``) is an isolated spike: taken as
        without bottom lock
        (:func:`sonarslam.datasets.gates.gate_dvl`); 0 turns the check off.
    ahrs_max_jump_deg : float
        An AHRS heading that differs from the last good one turned by the gyro's integral by
        more than this (deg), plus ``ahrs_jump_drift_deg_per_s`` per second since that sample, is a
        jump the gyro does not explain: dropped.
    ahrs_jump_drift_deg_per_s : float
        The allowance for the gyro's bias (deg/s).
    ahrs_max_rate_deg_per_s : float
        A gyro yaw rate beyond this (deg/s) is a spike: the sample is dropped.
    gps_max_jump_m : float
        A GPS fix farther than this (m), plus ``dvl_max_speed_mps`` times the time to its
        neighbours, from the median of its neighbours within 10 s is an outlier: dropped from the
        evaluation.
    gap_periods : float
        A sensor's gap is a time without a (valid) sample longer than this many of its median
        sampling periods ...
    min_gap_s : float
        ... and than this (s). The motion model takes a DVL or AHRS sample as stale from then
        on (:mod:`sonarslam.slam.model.motion`), so the covariance grows with the gap.
    """

    dvl_max_speed_mps: float = bounded(3.0, 0.0, 100.0, low_open=True)
    dvl_spike_sigmas: float = bounded(12.0, 0.0, 1e4)
    ahrs_max_jump_deg: float = bounded(10.0, 0.0, 180.0, low_open=True)
    ahrs_jump_drift_deg_per_s: float = bounded(1.0, 0.0, 360.0)
    ahrs_max_rate_deg_per_s: float = bounded(600.0, 0.0, 1e4, low_open=True)
    gps_max_jump_m: float = bounded(20.0, 0.0, 1e5, low_open=True)
    gap_periods: float = bounded(5.0, 1.0, 1e4)
    min_gap_s: float = bounded(1.0, 0.0, 3600.0, low_open=True)

    def __post_init__(self) -> None:
        check_fields(self)


#: What turns the estimators' heading between AHRS samples (``[motion] yaw_rate_source``):
#: ``"gyro"``, the logged yaw rate; ``"heading"``, the change of the AHRS heading since its
#: previous sample (causal). A gyro bias the estimators do not model (the marina's MTi,
#: docs/research/calibration.md) runs the closed-loop heading off the compass between heading updates.
YAW_RATE_SOURCES = ("gyro", "heading")
#: Largest clock offset of the sonar (s). A calibrated offset is a fraction of a second (the
#: marina's 0.75 s, docs/research/calibration.md); 10 s is most of a Miniking's 360 deg turn (~14 s),
#: over which every wall of a sector moves: a larger one is a unit slip (``150`` for 150 ms)
#: or clocks in other time zones, whose logs' times must be put right, not offset here.
MAX_TIME_OFFSET_S = 10.0


@dataclass(frozen=True)
class DatasetConfig:
    """Everything about a dataset that is not in its logs: the ``sonarslam.toml`` of the module
    docstring, angles in radians.

    Attributes
    ----------
    sonar : SonarHead
        The sonar head's geometry and its range offset (``[sonar]``).
    sonar_mounting, dvl_mounting, ahrs_mounting : Mounting
        Each sensor's frame in the body frame (x forward, y left), ``bTs``, ``bTd``, ``bTa``
        (``[mounting.*]``); identity by default.
    noise : NoiseConfig
        The 1-sigma sensor noise every estimator takes (``[noise]``).
    keyframe_scan_direction : {-1, 1}
        Keyframe datasets only (``[keyframes] scan_direction``): -1, the head turns toward
        decreasing angle, so a scan's ``i``-th beam has angle index ``-i mod n``; +1, the other way.
    sonar_time_offset_s : float
        Added to the sonar's log times to put its beams on the navigation clock (s;
        ``[sonar] time_offset_s``), within +- :data:`MAX_TIME_OFFSET_S`.
    yaw_rate_source : {"gyro", "heading"}
        What turns the estimators' heading between AHRS samples (``[motion]``,
        :data:`YAW_RATE_SOURCES`).
    ahrs_deviation_rad : (float, float)
        ``(B, C)``: the AHRS yaw errs by ``B sin(psi) + C cos(psi)`` around the body yaw
        ``psi`` (rad, each within +-pi/2; ``[motion] ahrs_deviation_deg``); the motion model
        takes it off.
    gates : GateConfig
        Plausibility of the sensors' samples (``[gates]``).

    Raises
    ------
    ValueError
        A field out of its range, or ``yaw_rate_source = "heading"`` with a walking AHRS bias
        (the heading would follow the walk).
    """

    sonar: SonarHead = field(default_factory=SonarHead)
    sonar_mounting: Mounting = field(default_factory=Mounting)
    dvl_mounting: Mounting = field(default_factory=Mounting)
    ahrs_mounting: Mounting = field(default_factory=Mounting)
    noise: NoiseConfig = field(default_factory=NoiseConfig)
    keyframe_scan_direction: int = one_of(-1, -1, 1)
    sonar_time_offset_s: float = bounded(0.0, -MAX_TIME_OFFSET_S, MAX_TIME_OFFSET_S)
    yaw_rate_source: str = one_of("gyro", *YAW_RATE_SOURCES)
    #: each of the two within +-pi/2 (:func:`sonarslam.settings.check_fields` checks a tuple's
    #: every element)
    ahrs_deviation_rad: tuple[float, float] = bounded((0.0, 0.0), -math.pi / 2, math.pi / 2)
    gates: GateConfig = field(default_factory=GateConfig)

    def __post_init__(self) -> None:
        check_fields(self)
        if self.yaw_rate_source == "heading" and self.noise.ahrs_bias_walk_deg_per_sqrt_s > 0.0:
            # the heading between AHRS samples would follow the AHRS's own change, walk and all,
            # while the back ends' bias state would be told it walks: not one model
            raise ValueError(
                "yaw_rate_source 'heading' turns the heading by the AHRS's own change, its bias"
                " walk included: with ahrs_bias_walk_deg_per_sqrt_s > 0 take 'gyro'"
            )


#: The abandoned marina (Ribas et al. 2008). How each mounting was calibrated is in docs/research/calibration.md.
MARINA_CONFIG = DatasetConfig(
    sonar=SonarHead(
        n_bins=500,
        bin_size_m=0.1,
        step_rad=math.radians(1.8),
        beam_width_rad=math.radians(3.0),
        angle_sense=-1,
    ),
    sonar_mounting=Mounting(
        yaw_rad=math.radians(154.75),
        source="sonar-map entropy over dead-reckoning poses, GPS-free (sonarslam calibrate)",
    ),
    dvl_mounting=Mounting(
        yaw_rad=math.radians(-90.0),
        source="vehicle's own DVL-to-body transform read off PID.log velocities (GPS-free)",
    ),
    ahrs_mounting=Mounting(
        yaw_rad=math.radians(-114.5),
        source="DVL compass minus MTi yaw, constant term of a fit over heading (its deviation"
        " averages out over headings, not over the run's time), minus 90 deg of DVL mount"
        " (GPS-free, sonarslam calibrate --ahrs)",
    ),
    # dvl_sigma_mps is the drift-causing part of the DVL's error (most of its scatter is the
    # vehicle's wobble); the nominal scatter is its usual level, the excess over it is added
    # (slam.model.noise.dvl_sample_sigma; sonarslam info prints the quantiles; GPS-free; the
    # figures are in docs/research/calibration.md).
    noise=NoiseConfig(
        dvl_sigma_mps=0.05,
        ahrs_sigma_deg=2.0,
        gps_sigma_m=1.0,
        dvl_scatter_window_s=60.0,
        dvl_nominal_scatter_mps=0.2,
        # a line's systematic error beyond its fit's: pairs of lines of one wall seen 14-30 s
        # apart with dead reckoning (sonarslam calibrate marina --line-noise, GPS-free)
        line_sigma_rho_m=0.425,
        line_sigma_theta_deg=2.35,
    ),
    keyframe_scan_direction=-1,
    # the sharpest map over dead-reckoning poses (benchmarks/marina_sonar_timing.py, GPS-free)
    sonar_time_offset_s=0.75,
    yaw_rate_source="heading",
    # the MTi yaw's hard-iron deviation, from the sonar lines of EKF closed loops (GPS-free):
    # sonarslam calibrate marina --ahrs-deviation (4 iterations, from 0)
    ahrs_deviation_rad=(math.radians(-2.01), math.radians(2.57)),
)


_DEGREES = "deg"

#: ``sonarslam.toml``: each table's keys and the :class:`DatasetConfig` field each sets
#: (dotted), with ``"deg"`` for the keys in degrees (fields in rad).
_SCHEMA: dict[str, dict[str, tuple[str, str | None]]] = {
    "sonar": {
        "n_bins": ("sonar.n_bins", None),
        "bin_size_m": ("sonar.bin_size_m", None),
        "step_deg": ("sonar.step_rad", _DEGREES),
        "beam_width_deg": ("sonar.beam_width_rad", _DEGREES),
        "angle_sense": ("sonar.angle_sense", None),
        "time_offset_s": ("sonar_time_offset_s", None),
        "range_offset_m": ("sonar.range_offset_m", None),
    },
    **{
        f"mounting.{name}": {
            "x_m": (f"{name}_mounting.x_m", None),
            "y_m": (f"{name}_mounting.y_m", None),
            "yaw_deg": (f"{name}_mounting.yaw_rad", _DEGREES),
            "source": (f"{name}_mounting.source", None),
        }
        for name in ("sonar", "dvl", "ahrs")
    },
    "noise": {f.name: (f"noise.{f.name}", None) for f in fields(NoiseConfig)},
    "keyframes": {"scan_direction": ("keyframe_scan_direction", None)},
    "motion": {
        "yaw_rate_source": ("yaw_rate_source", None),
        "ahrs_deviation_deg": ("ahrs_deviation_rad", _DEGREES),
    },
    "gates": {f.name: (f"gates.{f.name}", None) for f in fields(GateConfig)},
}


#: Keys of ``sonarslam.toml`` that were renamed, with their new names: an old one is an error
#: naming the new one (not an alias: one name per setting).
RENAMED_KEYS: dict[str, dict[str, str]] = {
    "gates": {
        "ahrs_jump_drift_dps": "ahrs_jump_drift_deg_per_s",
        "ahrs_max_rate_dps": "ahrs_max_rate_deg_per_s",
    },
}


def _field_type(path: str) -> Any:
    """The annotated type of a dotted :class:`DatasetConfig` field."""
    cls: Any = DatasetConfig
    *outer, name = path.split(".")
    for part in outer:
        cls = field_types(cls)[part]
    return field_types(cls)[name]


def _tables(p: Path, text: str, data: dict[str, Any]) -> dict[str, dict[str, Any]]:
    """The file's tables by dotted name (``mounting.sonar``); a key or a table that is not in
    the schema, or a value where a table belongs, is a DataError (with its line when found)."""
    out: dict[str, dict[str, Any]] = {}
    for name, table in data.items():
        if name in ("topics", "ping360", "navlog"):  # a bag's roles (datasets.rosbag), a Ping
            continue  # Viewer log's own settings (datasets.ping360), a navigation log's (navlog)
        if name == "mounting" and isinstance(table, dict):
            for sub, inner in table.items():
                out.update(_tables(p, text, {f"mounting.{sub}": inner}))
            continue
        outer, _, last = name.rpartition(".")
        line = toml_line(text, outer, last) or toml_line(text, name)
        if name not in _SCHEMA and name != "mounting":
            # the tables allowed where the unknown one is: [mounting]'s own, or the top level's
            allowed = sorted(
                {k[len(outer) + 1 :] for k in _SCHEMA if k.startswith(f"{outer}.")}
                if outer
                else {k.split(".")[0] for k in _SCHEMA}
            )
            where = f"[{outer}]" if outer else "top level"
            raise DataError(p, line, f"unknown key {last!r} in {where}; allowed: {allowed}")
        if not isinstance(table, dict):
            raise DataError(
                p, line, f"[{name}] must be a table, got {table!r} ({type(table).__name__})"
            )
        unknown = sorted(set(table) - set(_SCHEMA[name]))
        renamed = [k for k in unknown if k in RENAMED_KEYS.get(name, {})]
        if renamed:
            new = RENAMED_KEYS[name][renamed[0]]
            raise DataError(
                p,
                toml_line(text, name, renamed[0]),
                f"[{name}] {renamed[0]} was renamed {new} (one unit suffix per unit: deg/s is"
                f" _deg_per_s); write {new} = ...",
            )
        if unknown:
            raise DataError(
                p,
                toml_line(text, name, unknown[0]),
                f"unknown key(s) {unknown} in [{name}]; allowed: {sorted(_SCHEMA[name])}",
            )
        out[name] = table
    return out


def load_dataset_config(path: str | Path, base: DatasetConfig | None = None) -> DatasetConfig:
    """Read a ``sonarslam.toml`` over ``base`` (default: a plain :class:`DatasetConfig`).

    Raises
    ------
    DataError
        A file that cannot be read or is not UTF-8 (with its line), a TOML syntax error (with
        its line), a table that is not one, an unknown key, a value of the wrong type,
        non-finite or out of range (naming the key, and its line when written ``key = ...``;
        :mod:`sonarslam.settings`).
    """
    p = Path(path)
    base = base if base is not None else DatasetConfig()
    data, text = read_toml(p)
    changes: dict[str, Any] = {}
    keys: dict[str, tuple[str, str]] = {}  # field path -> the file's table and key
    try:
        for table, values in _tables(p, text, data).items():
            for key, value in values.items():
                target, unit = _SCHEMA[table][key]
                keys[target] = (table, key)
                typed = coerce(_field_type(target), value, f"[{table}] {key}", parse_strings=False)
                if unit == _DEGREES:
                    typed = (
                        tuple(math.radians(v) for v in typed)
                        if isinstance(typed, tuple)
                        else math.radians(typed)
                    )
                changes[target] = typed
            if table.startswith("mounting.") and "source" not in values:
                changes[f"{table.split('.')[1]}_mounting.source"] = str(p)
        return replace_checked(base, changes)  # type: ignore[no-any-return]
    except SettingError as exc:
        # the file's keys among those named (a mounting's source is set here, not by the file)
        named = [n for n in (keys.get(k.strip()) for k in exc.key.split(",")) if n is not None]
        where = [f"[{t}] {k}" for t, k in named]
        line = toml_line(text, *named[0]) if len(named) == 1 else None
        if not where:  # a type error, already named by the file's key
            where, line = [exc.key], _line_of_key(text, exc.key)
        message = exc.message
        if len(named) == 1 and _SCHEMA[named[0][0]][named[0][1]][1] == _DEGREES:
            message = _in_degrees(_SCHEMA[named[0][0]][named[0][1]][0], data, named[0], message)
        raise DataError(p, line, f"{', '.join(where)}: {message}") from None


def _in_degrees(path: str, data: dict[str, Any], table_key: tuple[str, str], message: str) -> str:
    """The range check's ``message`` of a key in degrees restated in degrees (the field's range
    is in radians), with the value as the file wrote it."""
    cls: Any = DatasetConfig
    *outer, name = path.split(".")
    for part in outer:
        cls = field_types(cls)[part]
    r = next((f.metadata.get("range") for f in fields(cls) if f.name == name), None)
    if r is None or " must be in " not in f" {message}":
        return message
    table, key = table_key
    value: Any = data
    for part in (*table.split("."), key):
        value = value.get(part) if isinstance(value, dict) else None
    lb, rb = "(" if r.low_open else "[", ")" if r.high_open else "]"
    return f"must be in {lb}{_deg(r.low):g}, {_deg(r.high):g}{rb} deg, got {value!r}"


def _line_of_key(text: str, key: str) -> int | None:
    """The line of a ``"[table] key"`` name."""
    found = re.fullmatch(r"\[(.+)\] (.+)", key)
    return toml_line(text, found.group(1), found.group(2)) if found else None


def _deg(angle_rad: float) -> float:
    """Degrees to 12 significant digits (1.8, not 1.8000000000001186)."""
    return float(f"{math.degrees(angle_rad):.12g}")


def config_tables(config: DatasetConfig) -> dict[str, dict[str, Any]]:
    """The ``sonarslam.toml`` tables of ``config``: ``{"sonar": {...}, "mounting.sonar": {...},
    ...}``, every key with its value in the file's units (what :func:`dump_dataset_config`
    writes and ``sonarslam info`` prints)."""

    def mount(m: Mounting) -> dict[str, Any]:
        return {"x_m": m.x_m, "y_m": m.y_m, "yaw_deg": _deg(m.yaw_rad), "source": m.source}

    s = config.sonar
    return {
        "sonar": {
            "n_bins": s.n_bins,
            "bin_size_m": s.bin_size_m,
            "step_deg": _deg(s.step_rad),
            "beam_width_deg": _deg(s.beam_width_rad),
            "angle_sense": s.angle_sense,
            "time_offset_s": config.sonar_time_offset_s,
            "range_offset_m": s.range_offset_m,
        },
        "mounting.sonar": mount(config.sonar_mounting),
        "mounting.dvl": mount(config.dvl_mounting),
        "mounting.ahrs": mount(config.ahrs_mounting),
        "noise": {f.name: getattr(config.noise, f.name) for f in fields(NoiseConfig)},
        "keyframes": {"scan_direction": config.keyframe_scan_direction},
        "motion": {
            "yaw_rate_source": config.yaw_rate_source,
            "ahrs_deviation_deg": [_deg(v) for v in config.ahrs_deviation_rad],
        },
        "gates": {f.name: getattr(config.gates, f.name) for f in fields(GateConfig)},
    }


def dump_dataset_config(config: DatasetConfig) -> str:
    """The TOML text of ``config`` (what the simulator writes beside its logs), by tomli-w;
    ``[gates]`` only when it differs from the defaults (the file stays what it was otherwise).
    Arrays of numbers stay on their key's line (``ahrs_deviation_deg = [-2.01, 2.57]``), so
    that an error in one names the line that holds it."""
    doc: dict[str, Any] = {}
    for name, table in config_tables(config).items():
        if name == "gates" and config.gates == GateConfig():
            continue
        head, _, sub = name.partition(".")
        if sub:
            doc.setdefault(head, {})[sub] = table
        else:
            doc[head] = table
    return _ONE_LINE_ARRAY.sub(_join_array, tomli_w.dumps(doc))


#: tomli-w's multi-line array of plain numbers: ``key = [\n    1.0,\n    2.0,\n]``
_ONE_LINE_ARRAY = re.compile(r"= \[\n((?:    [-+0-9.eE]+,\n)+)\]")


def _join_array(match: re.Match[str]) -> str:
    return "= [" + ", ".join(v.strip().rstrip(",") for v in match.group(1).splitlines()) + "]"
