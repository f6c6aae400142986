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

    [noise]                 # 1-sigma sensor noise used by the estimators
    dvl_sigma_mps = 0.05
    ahrs_sigma_deg = 2.0
    gps_sigma_m = 1.0
    dvl_max_gap_s = 10.0    # a DVL dropout longer than this inflates the velocity noise
    dvl_scatter_window_s = 60.0     # the DVL's own scatter over this window (0: off) ...
    dvl_nominal_scatter_mps = 0.2   # ... beyond its usual scatter is white noise added to
                            # dvl_sigma_mps (sonarslam info prints the scatter's quantiles)
    ahrs_bias_walk_deg_per_sqrt_s = 0.0  # the AHRS bias's random walk (0: a constant bias)
    dvl_scale_sigma = 0.0   # 1-sigma of the DVL's scale-factor error (0: none)
    line_sigma_rho_m = 0.0  # a line's systematic error, added to every line's covariance
    line_sigma_theta_deg = 0.0      # (sonarslam calibrate --line-noise, GPS-free)

    [motion]
    yaw_rate_source = "heading"  # what turns the heading between AHRS samples: "gyro" (the
                            # logged rate) or "heading" (the AHRS heading's own change)
    ahrs_deviation_deg = [-2.01, 2.57]  # the AHRS yaw errs by B sin(yaw) + C cos(yaw) (deg):
                            # taken off (sonarslam calibrate --ahrs-deviation)

Keys a file leaves out take the neutral defaults of :class:`DatasetConfig` (no clock offset,
identity mountings); the simulator writes every key. Without a file, a dataset gets the marina's
calibration (see ``MARINA_CONFIG`` and the
README's "Calibration" section for how each number was found and whether GPS was used).
"""

from __future__ import annotations

import math
import re
import tomllib
from dataclasses import dataclass, field, fields, replace
from pathlib import Path
from typing import Any

import tomli_w

from datasets.errors import DataError
from sonar.beam import Mounting, SonarHead

__all__ = [
    "NoiseConfig",
    "DatasetConfig",
    "MARINA_CONFIG",
    "load_dataset_config",
    "config_tables",
    "dump_dataset_config",
]


@dataclass(frozen=True)
class NoiseConfig:
    """1-sigma noise of the navigation sensors, as used by the estimators."""

    dvl_sigma_mps: float = 0.05
    ahrs_sigma_deg: float = 2.0
    gps_sigma_m: float = 1.0
    dvl_max_gap_s: float = 10.0
    #: 0 turns the excess-scatter DVL noise off (slam.model.motion.dvl_sample_sigma)
    dvl_scatter_window_s: float = 0.0
    dvl_nominal_scatter_mps: float = 0.0
    #: the AHRS heading bias's random walk (deg/sqrt(s)), 0: constant (the back ends' state)
    ahrs_bias_walk_deg_per_sqrt_s: float = 0.0
    #: 1-sigma of the DVL's scale-factor error (a ratio), 0: none (estimated by the back ends)
    dvl_scale_sigma: float = 0.0
    #: a line's systematic error (m, deg), added to every line's covariance by the extractor
    line_sigma_rho_m: float = 0.0
    line_sigma_theta_deg: float = 0.0


#: What turns the estimators' heading between AHRS samples (``[motion] yaw_rate_source``):
#: ``"gyro"``, the logged yaw rate; ``"heading"``, the change of the AHRS heading since its
#: previous sample (causal). A gyro bias the estimators do not model (the marina's MTi, README
#: "Calibration") runs the closed-loop heading off the compass between heading updates.
YAW_RATE_SOURCES = ("gyro", "heading")


@dataclass(frozen=True)
class DatasetConfig:
    """Everything about a dataset that is not in its logs."""

    sonar: SonarHead = field(default_factory=SonarHead)
    sonar_mounting: Mounting = field(default_factory=Mounting)
    dvl_mounting: Mounting = field(default_factory=Mounting)
    ahrs_mounting: Mounting = field(default_factory=Mounting)
    noise: NoiseConfig = field(default_factory=NoiseConfig)
    keyframe_scan_direction: int = -1
    sonar_time_offset_s: float = 0.0
    yaw_rate_source: str = "gyro"
    ahrs_deviation_rad: tuple[float, float] = (0.0, 0.0)

    def __post_init__(self) -> None:
        if self.yaw_rate_source not in YAW_RATE_SOURCES:
            raise ValueError(
                f"yaw_rate_source must be one of {YAW_RATE_SOURCES}, got {self.yaw_rate_source!r}"
            )


#: The abandoned marina (Ribas et al. 2008). How each mounting was calibrated is in README.md.
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
    # figures are in README.md, "Calibration").
    noise=NoiseConfig(
        dvl_sigma_mps=0.05,
        ahrs_sigma_deg=2.0,
        gps_sigma_m=1.0,
        dvl_scatter_window_s=60.0,
        dvl_nominal_scatter_mps=0.2,
    ),
    keyframe_scan_direction=-1,
    # the sharpest map over dead-reckoning poses (benchmarks/marina_sonar_timing.py, GPS-free)
    sonar_time_offset_s=0.75,
    yaw_rate_source="heading",
    # the MTi yaw's hard-iron deviation, from the sonar lines of EKF closed loops (GPS-free):
    # sonarslam calibrate marina --ahrs-deviation (4 iterations, from 0)
    ahrs_deviation_rad=(math.radians(-2.01), math.radians(2.57)),
)


def _check_keys(path: Path, table: str, data: dict[str, Any], allowed: set[str]) -> None:
    unknown = set(data) - allowed
    if unknown:
        raise DataError(
            path, None, f"unknown key(s) {sorted(unknown)} in [{table}]; allowed: {sorted(allowed)}"
        )


def _number(
    path: Path, table: str, key: str, value: Any, *, positive: bool = False, integer: bool = False
) -> float:
    """A finite number from a TOML value (optionally > 0, optionally whole), else DataError."""
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
        raise DataError(path, None, f"[{table}] {key} must be a finite number, got {value!r}")
    if integer and float(value) != int(value):
        raise DataError(path, None, f"[{table}] {key} must be a whole number, got {value!r}")
    if positive and not value > 0:
        raise DataError(path, None, f"[{table}] {key} must be > 0, got {value!r}")
    return float(value)


def _mounting(path: Path, table: str, data: dict[str, Any], default: Mounting) -> Mounting:
    _check_keys(path, table, data, {"x_m", "y_m", "yaw_deg", "source"})
    kwargs: dict[str, Any] = {}
    for key in ("x_m", "y_m"):
        if key in data:
            kwargs[key] = _number(path, table, key, data[key])
    if "yaw_deg" in data:
        kwargs["yaw_rad"] = math.radians(_number(path, table, "yaw_deg", data["yaw_deg"]))
    kwargs["source"] = str(data.get("source", f"{path}"))
    return replace(default, **kwargs)


def _sonar_table(p: Path, s: dict[str, Any], base: DatasetConfig) -> tuple[SonarHead, float]:
    """``[sonar]`` over ``base``: the head and the clock offset."""
    _check_keys(
        p,
        "sonar",
        s,
        {
            "n_bins",
            "bin_size_m",
            "step_deg",
            "beam_width_deg",
            "angle_sense",
            "time_offset_s",
            "range_offset_m",
        },
    )
    kwargs: dict[str, Any] = {}
    if "n_bins" in s:
        kwargs["n_bins"] = int(
            _number(p, "sonar", "n_bins", s["n_bins"], positive=True, integer=True)
        )
    if "bin_size_m" in s:
        kwargs["bin_size_m"] = _number(p, "sonar", "bin_size_m", s["bin_size_m"], positive=True)
    if "step_deg" in s:
        kwargs["step_rad"] = math.radians(
            _number(p, "sonar", "step_deg", s["step_deg"], positive=True)
        )
    if "beam_width_deg" in s:
        kwargs["beam_width_rad"] = math.radians(
            _number(p, "sonar", "beam_width_deg", s["beam_width_deg"], positive=True)
        )
    if "angle_sense" in s:
        kwargs["angle_sense"] = int(
            _number(p, "sonar", "angle_sense", s["angle_sense"], integer=True)
        )
    if "range_offset_m" in s:
        kwargs["range_offset_m"] = _number(p, "sonar", "range_offset_m", s["range_offset_m"])
    time_offset_s = base.sonar_time_offset_s
    if "time_offset_s" in s:
        time_offset_s = _number(p, "sonar", "time_offset_s", s["time_offset_s"])
    try:
        return replace(base.sonar, **kwargs), time_offset_s
    except ValueError as exc:
        raise DataError(p, None, f"[sonar] {exc}") from exc


def _noise_table(p: Path, table: dict[str, Any], base: NoiseConfig) -> NoiseConfig:
    """``[noise]`` over ``base``: finite, positive (the scatter settings may be 0)."""
    _check_keys(p, "noise", table, {f.name for f in fields(NoiseConfig)})
    may_be_zero = {
        "dvl_scatter_window_s",
        "dvl_nominal_scatter_mps",
        "ahrs_bias_walk_deg_per_sqrt_s",
        "dvl_scale_sigma",
        "line_sigma_rho_m",
        "line_sigma_theta_deg",
    }
    values = {}
    for k, v in table.items():
        values[k] = _number(p, "noise", k, v, positive=k not in may_be_zero)
        if values[k] < 0:
            raise DataError(p, None, f"[noise] {k} must be >= 0, got {v!r}")
    return replace(base, **values)


def _motion_table(
    p: Path, table: dict[str, Any], base: DatasetConfig
) -> tuple[str, tuple[float, float]]:
    """``[motion]`` over ``base``: the yaw-rate source and the AHRS deviation (rad)."""
    _check_keys(p, "motion", table, {"yaw_rate_source", "ahrs_deviation_deg"})
    yaw_rate_source = base.yaw_rate_source
    if "yaw_rate_source" in table:
        yaw_rate_source = table["yaw_rate_source"]
        if yaw_rate_source not in YAW_RATE_SOURCES:
            raise DataError(
                p,
                None,
                f"[motion] yaw_rate_source must be one of {YAW_RATE_SOURCES},"
                f" got {yaw_rate_source!r}",
            )
    deviation = base.ahrs_deviation_rad
    if "ahrs_deviation_deg" in table:
        dev = table["ahrs_deviation_deg"]
        if not isinstance(dev, list) or len(dev) != 2:
            raise DataError(
                p, None, f"[motion] ahrs_deviation_deg must be [B, C] (deg), got {dev!r}"
            )
        b_deg, c_deg = (_number(p, "motion", "ahrs_deviation_deg", v) for v in dev)
        deviation = (math.radians(b_deg), math.radians(c_deg))
    return yaw_rate_source, deviation


def load_dataset_config(path: str | Path, base: DatasetConfig | None = None) -> DatasetConfig:
    """Read a ``sonarslam.toml`` over ``base`` (default: a plain :class:`DatasetConfig`).

    Raises
    ------
    DataError
        On a TOML syntax error (with its line), an unknown key or a value of the wrong type.
    """
    p = Path(path)
    base = base if base is not None else DatasetConfig()
    try:
        data = tomllib.loads(p.read_text(encoding="utf-8"))
    except tomllib.TOMLDecodeError as exc:
        found = re.search(r"at line (\d+)", str(exc))
        raise DataError(
            p, int(found.group(1)) if found else None, f"TOML syntax error: {exc}"
        ) from exc
    except OSError as exc:
        raise DataError(p, None, f"cannot read: {exc.strerror}") from exc
    _check_keys(p, "top level", data, {"sonar", "mounting", "noise", "keyframes", "motion"})

    sonar, time_offset_s = base.sonar, base.sonar_time_offset_s
    if "sonar" in data:
        sonar, time_offset_s = _sonar_table(p, data["sonar"], base)
    mountings = {"sonar": base.sonar_mounting, "dvl": base.dvl_mounting, "ahrs": base.ahrs_mounting}
    if "mounting" in data:
        _check_keys(p, "mounting", data["mounting"], set(mountings))
        for name, table in data["mounting"].items():
            mountings[name] = _mounting(p, f"mounting.{name}", table, mountings[name])
    noise = _noise_table(p, data["noise"], base.noise) if "noise" in data else base.noise
    scan_direction = base.keyframe_scan_direction
    if "keyframes" in data:
        _check_keys(p, "keyframes", data["keyframes"], {"scan_direction"})
        scan_direction = int(
            _number(p, "keyframes", "scan_direction", data["keyframes"]["scan_direction"])
        )
        if scan_direction not in (-1, 1):
            raise DataError(
                p, None, f"[keyframes] scan_direction must be +1 or -1, got {scan_direction}"
            )
    yaw_rate_source, ahrs_deviation_rad = base.yaw_rate_source, base.ahrs_deviation_rad
    if "motion" in data:
        yaw_rate_source, ahrs_deviation_rad = _motion_table(p, data["motion"], base)
    return DatasetConfig(
        sonar=sonar,
        sonar_mounting=mountings["sonar"],
        dvl_mounting=mountings["dvl"],
        ahrs_mounting=mountings["ahrs"],
        noise=noise,
        keyframe_scan_direction=scan_direction,
        sonar_time_offset_s=time_offset_s,
        yaw_rate_source=yaw_rate_source,
        ahrs_deviation_rad=ahrs_deviation_rad,
    )


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
    }


def dump_dataset_config(config: DatasetConfig) -> str:
    """The TOML text of ``config`` (what the simulator writes beside its logs), by tomli-w."""
    doc: dict[str, Any] = {}
    for name, table in config_tables(config).items():
        head, _, sub = name.partition(".")
        if sub:
            doc.setdefault(head, {})[sub] = table
        else:
            doc[head] = table
    return tomli_w.dumps(doc)
