"""Presets and overrides: the one place where a run's extractor and back-end settings are decided.

* Extractor presets (:data:`EXTRACTOR_PRESETS`), chosen by the kind of beams
  (:func:`preset_for`): ``default`` for raw intensity beams (the simulator, ``*_IS.log``),
  ``marina`` for thresholded 0/255 keyframes (the marina), as the closed loops use them. Every
  command that extracts lines (``run``, ``extract``, ``calibrate --ahrs-deviation``, the sweep,
  the benchmarks and notebooks) takes them from here and records the preset's name.
* Back-end configurations: each back end's defaults (:mod:`slam.backends.registry`), with
  settings over them.
* A dataset's calibration of the sensors' noise (``[noise]`` of its ``sonarslam.toml``,
  :class:`datasets.config.NoiseConfig`) goes over the preset and the defaults, under a TOML
  file's and the settings: a line's systematic error (``line_sigma_rho_m``,
  ``line_sigma_theta_deg``) into the extractor, the AHRS bias's random walk into the back end
  (:func:`noise_settings`).
* Settings given as ``SCOPE.FIELD=VALUE`` (``sonarslam run --set``, ``sonarslam sweep --grid``):
  ``SCOPE`` is ``extractor`` (:class:`features.extractor.ExtractorConfig`), ``scans`` (the scan
  matcher, :class:`features.scans.ScanConfig`, when the back end's ``constraints`` hold
  ``scans``) or a back end's name
  (``ekf``: :class:`slam.backends.ekf.EkfConfig`, ``isam2``:
  :class:`slam.backends.isam2.graph.GraphConfig`); ``FIELD`` is a field of that frozen
  dataclass, nested by dots (``ekf.association.gate_probability``); ``<backend>.association``
  is short for ``<backend>.association.method``.
"""

from __future__ import annotations

import dataclasses
import math
import tomllib
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from datasets.config import NoiseConfig
from features.config import ExtractorConfig
from features.scans import ScanConfig
from slam.backends.base import BackendConfig
from slam.backends.registry import backend_spec
from sonar.beam import SonarBeam
from sonar.store import sector_beam_count

__all__ = [
    "EXTRACTOR_PRESETS",
    "SCAN_PRESETS",
    "RunConfig",
    "preset_for",
    "extractor_config",
    "pool_preset",
    "map_min_intensity",
    "backend_config",
    "run_config",
    "parse_value",
    "parse_settings",
    "apply_overrides",
    "split_settings",
]

_DEG = math.pi / 180.0

#: The marina keyframes (datasets/marina/README.md): Miniking, 1.8 deg step, 0.1 m bins, 50 m
#: range, 3 deg beam; beams are 0/255 masks (a third party's threshold, first 10 bins dropped),
#: with ~0.7 echo runs of ~3 m per beam. The first return of each run votes; the line's
#: covariance is the paper's overlap-ratio ellipse ("seed"), which matches the scatter of
#: repeated lines of one wall on these metres-thick echo bands where the least-squares one is
#: far too small (README, "Line features on the marina"); a 360 deg sector gives longer
#: segments; the odometry's uncertainty over the sector is added (it grows when the DVL
#: degrades).
_MARINA = ExtractorConfig(
    intensity_threshold=1.0,  # unused for masks: every given bin is a threshold bin
    max_intensity_difference=0.0,  # masks: all bins equal, all kept
    min_distance_m=1.0,  # keep the first return of each run (runs are ~3 m thick)
    min_range_m=1.0,  # the keyframes drop the bins below 1 m anyway
    sector_deg=360.0,  # 200 beams
    incidence_beta_rad=25.0 * _DEG,
    theta_res_rad=1.8 * _DEG,  # the head step
    rho_res_m=0.3,  # 3 bins: the first bin of a smoothed echo jitters by a few bins
    min_votes=15,
    suppress_theta_cells=1,
    suppress_rho_cells=2,
    vote_every_n_beams=20,  # 36 deg of scan between votes
    return_model="first_return",  # the nearest bin of each run of a mask
    range_sigma_m=0.15,
    requery_poses=True,
    covariance_method="seed",
    pose_uncertainty=True,
)

#: Extractor presets by name (module docstring).
EXTRACTOR_PRESETS: dict[str, ExtractorConfig] = {
    "default": ExtractorConfig(),
    "marina": _MARINA,
    # the same with the least-squares covariance over a 180 deg sector and 10 votes: more,
    # shorter lines whose covariance describes the sonar's own noise only
    "marina-fit": _MARINA.replace(
        sector_deg=180.0, min_votes=10, covariance_method="fit", pose_uncertainty=False
    ),
}


#: Scan matcher presets by the same names (:func:`preset_for`): the systematic error of a
#: registration beyond its Hessian (``floor_sigma_m``, ``floor_sigma_deg``). ``default`` (raw
#: beams): measured on the simulator against its truth (``benchmarks/marina_registration.py
#: --source DIR``: NEES of revisits in their band); ``marina`` (thresholded keyframes): the
#: scatter of consecutive registrations about dead reckoning's relative pose, GPS-free (README,
#: "Scan matching").
SCAN_PRESETS: dict[str, ScanConfig] = {
    "default": ScanConfig(),
    "marina": ScanConfig(floor_sigma_m=0.5, floor_sigma_deg=1.0),
    "marina-fit": ScanConfig(floor_sigma_m=0.5, floor_sigma_deg=1.0),
}


def preset_for(beams: Sequence[SonarBeam]) -> str:
    """``"marina"`` for thresholded beams (0/255 masks, as the marina keyframes), else
    ``"default"`` (raw intensities)."""
    return "marina" if beams and all(b.thresholded for b in beams) else "default"


def _read_table(path: str | Path, table: str) -> dict[str, Any]:
    with open(path, "rb") as f:
        data = tomllib.load(f)
    inner = data.get(table, data)
    if not isinstance(inner, dict):
        raise ValueError(f"{path}: [{table}] must be a table")
    return inner


def noise_settings(noise: NoiseConfig | None) -> tuple[dict[str, Any], dict[str, Any]]:
    """``(extractor fields, back-end fields)`` a dataset's ``[noise]`` calibration sets."""
    if noise is None:
        return {}, {}
    ext = {
        "line_sigma_rho_m": noise.line_sigma_rho_m,
        "line_sigma_theta_rad": math.radians(noise.line_sigma_theta_deg),
    }
    return ext, {"ahrs_bias_walk_deg_per_sqrt_s": noise.ahrs_bias_walk_deg_per_sqrt_s}


def extractor_config(
    preset: str,
    config_path: str | Path | None = None,
    overrides: dict[str, Any] | None = None,
    noise: NoiseConfig | None = None,
) -> ExtractorConfig:
    """A preset, with a dataset's ``noise`` calibration (:func:`noise_settings`), the fields of a
    TOML file (``[extractor]`` table or top level) and then ``overrides`` (dotted names,
    :func:`apply_overrides`) over it.

    Raises ValueError for an unknown preset or field.
    """
    if preset not in EXTRACTOR_PRESETS:
        raise ValueError(
            f"extractor preset must be one of {sorted(EXTRACTOR_PRESETS)}, got {preset!r}"
        )
    config = EXTRACTOR_PRESETS[preset].replace(**noise_settings(noise)[0])
    if config_path is not None:
        data = _read_table(config_path, "extractor")
        unknown = set(data) - {f.name for f in dataclasses.fields(ExtractorConfig)}
        if unknown:
            raise ValueError(f"{config_path}: unknown ExtractorConfig fields: {sorted(unknown)}")
        config = config.replace(**data)
    return apply_overrides(config, overrides or {})


def pool_preset(step_rad: float, covariance_method: str = "fit") -> ExtractorConfig:
    """The seed paper's pool test (section 3): 270 deg sector, beta 25 deg, min votes 15, one
    vote per full sector (``vote_every_n_beams`` = the sector's beams, 600 at 0.45 deg); the
    rest are the extractor's defaults."""
    sector_deg = 270.0
    return ExtractorConfig(
        sector_deg=sector_deg,
        incidence_beta_rad=25.0 * _DEG,
        min_votes=15,
        vote_every_n_beams=sector_beam_count(sector_deg * _DEG, step_rad),
        covariance_method=covariance_method,
    )


def map_min_intensity(beams: Sequence[SonarBeam], config: ExtractorConfig | None = None) -> int:
    """Smallest intensity drawn in maps: every given bin of thresholded beams, else the bins at
    or above the extractor's intensity threshold (``config``'s, default the beams' preset's):
    raw beams are mostly background noise."""
    if beams and all(b.thresholded for b in beams):
        return 1
    threshold = (config or EXTRACTOR_PRESETS[preset_for(beams)]).intensity_threshold
    return max(int(np.ceil(threshold)), 1)


def backend_config(
    name: str, overrides: dict[str, Any] | None = None, noise: NoiseConfig | None = None
) -> BackendConfig:
    """Back end ``name``'s default configuration with a dataset's ``noise`` calibration
    (:func:`noise_settings`) and ``overrides`` (dotted names) over it."""
    defaults = dataclasses.replace(backend_spec(name).config_type(), **noise_settings(noise)[1])
    return apply_overrides(defaults, overrides or {})


@dataclass(frozen=True)
class RunConfig:
    """The settings of one closed-loop run, decided here.

    Attributes
    ----------
    preset : str
        The extractor preset's name.
    extractor : ExtractorConfig
        The preset with the run's ``extractor.*`` settings over it.
    backend : BackendConfig
        The back end's defaults with its ``<backend>.*`` settings over them.
    settings : dict
        The settings given (``SCOPE.FIELD`` -> value), for ``metrics.json``.
    scans : ScanConfig
        The scan matcher's preset of the same name (:data:`SCAN_PRESETS`) with the ``scans.*``
        settings over it (used when the back end's ``constraints`` hold ``scans``).
    """

    preset: str
    extractor: ExtractorConfig
    backend: BackendConfig
    settings: dict[str, Any]
    scans: ScanConfig = ScanConfig()


def run_config(
    beams: Sequence[SonarBeam],
    backend: str,
    settings: dict[str, Any] | None = None,
    noise: NoiseConfig | None = None,
) -> RunConfig:
    """The extractor and back-end configurations of a closed loop of ``backend`` on these beams
    and a dataset's ``noise`` calibration, with ``settings`` (``{"isam2.robust": "cauchy",
    "extractor.min_votes": 12}``) applied."""
    given = dict(settings or {})
    scans = {k.partition(".")[2]: v for k, v in given.items() if k.startswith("scans.")}
    ext, own = split_settings(
        {k: v for k, v in given.items() if not k.startswith("scans.")}, backend
    )
    preset = preset_for(beams)
    return RunConfig(
        preset,
        extractor_config(preset, overrides=ext, noise=noise),
        backend_config(backend, own, noise),
        given,
        apply_overrides(SCAN_PRESETS[preset], scans),
    )


_ALIASES = {"association": "association.method"}


def parse_value(text: str) -> Any:
    """A setting value: int, float, true/false, none, else the string itself."""
    t = text.strip()
    low = t.lower()
    if low in ("true", "false"):
        return low == "true"
    if low in ("none", "null"):
        return None
    for kind in (int, float):
        try:
            return kind(t)
        except ValueError:
            pass
    return t


def parse_settings(specs: Iterable[str]) -> dict[str, Any]:
    """``{"ekf.extent_margin_m": 10.0}`` from ``["ekf.extent_margin_m=10"]``."""
    out: dict[str, Any] = {}
    for spec in specs:
        name, sep, value = spec.partition("=")
        name = name.strip()
        if not sep or "." not in name or not value.strip():
            raise ValueError(f"--set: expected SCOPE.FIELD=VALUE, got {spec!r}")
        out[name] = parse_value(value)
    return out


def _set_path(config: Any, path: Sequence[str], value: Any) -> Any:
    if not dataclasses.is_dataclass(config) or isinstance(config, type):
        raise ValueError(f"cannot set {'.'.join(path)} on a {type(config).__name__}")
    names = [f.name for f in dataclasses.fields(config)]
    if path[0] not in names:
        raise ValueError(f"unknown field {path[0]!r} of {type(config).__name__}; one of {names}")
    if len(path) == 1:
        return dataclasses.replace(config, **{path[0]: value})
    inner = _set_path(getattr(config, path[0]), path[1:], value)
    return dataclasses.replace(config, **{path[0]: inner})


def apply_overrides(config: Any, overrides: dict[str, Any]) -> Any:
    """``config`` with dotted fields (``"association.method"``, aliases too) replaced."""
    for name, value in overrides.items():
        path = _ALIASES.get(name, name).split(".")
        config = _set_path(config, path, value)
    return config


def split_settings(params: dict[str, Any], backend: str) -> tuple[dict[str, Any], dict[str, Any]]:
    """``(extractor settings, back-end settings)`` of ``params`` for ``backend``; a setting of
    another scope is an error naming it."""
    ext: dict[str, Any] = {}
    own: dict[str, Any] = {}
    for name, value in params.items():
        scope, _, rest = name.partition(".")
        if scope == "extractor":
            ext[rest] = value
        elif scope == backend:
            own[rest] = value
        else:
            raise ValueError(f"parameter {name!r} does not apply to back end {backend!r}")
    return ext, own
