"""Presets and overrides: the one place where a run's extractor and back-end settings are decided.

* Extractor presets (:data:`EXTRACTOR_PRESETS`), chosen by the kind of beams
  (:func:`preset_for`): ``default`` for raw intensity beams (the simulator, ``*_IS.log``),
  ``marina`` for thresholded 0/255 keyframes (the marina), as the closed loops use them. Every
  command that extracts lines (``run``, ``extract``, ``calibrate --ahrs-deviation``, the sweep,
  the benchmarks and notebooks) takes them from here and records the preset's name.
* Back-end configurations: each back end's defaults (:mod:`sonarslam.slam.backends.registry`), with
  settings over them.
* A dataset's calibration of the sensors' noise (``[noise]`` of its ``sonarslam.toml``,
  :class:`sonarslam.datasets.config.NoiseConfig`) goes over the preset and the defaults, under a TOML
  file's and the settings: a line's systematic error (``line_sigma_rho_m``,
  ``line_sigma_theta_deg``) into the extractor (:func:`noise_settings`), the whole table into
  the back end as its ``noise`` (the AHRS's white noise, bias and walk, the gyro's noise, the
  DVL's scale-factor error).
* Settings given as ``SCOPE.FIELD=VALUE`` (``sonarslam run --set``, ``sonarslam sweep --grid``):
  ``SCOPE`` is ``extractor`` (:class:`sonarslam.features.extractor.ExtractorConfig`), ``scans`` (the scan
  matcher, :class:`sonarslam.features.scans.ScanConfig`, when the back end's ``constraints`` hold
  ``scans``) or a back end's name
  (``ekf``: :class:`sonarslam.slam.backends.ekf.EkfConfig`, ``isam2``:
  :class:`sonarslam.slam.backends.isam2.graph.GraphConfig`); ``FIELD`` is a field of that frozen
  dataclass, nested by dots (``ekf.association.gate_probability``); ``<backend>.association``
  is short for ``<backend>.association.method``. Every value is checked against the field's
  type and the dataclass's ranges (:mod:`sonarslam.settings`, the mechanism that also checks
  ``sonarslam.toml``): a wrong one is a :class:`sonarslam.settings.SettingError` naming it.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from sonarslam.datasets.config import NoiseConfig
from sonarslam.datasets.errors import DataError
from sonarslam.datasets.records import BeamSeries
from sonarslam.datasets.source import Dataset
from sonarslam.datasets.toml import read_toml, toml_line
from sonarslam.features.config import ExtractorConfig
from sonarslam.features.scans import ScanConfig
from sonarslam.settings import SettingError, parse_text, replace_checked
from sonarslam.slam.backends.base import BACKEND_NOISE_KEYS, BackendConfig
from sonarslam.slam.backends.registry import BACKENDS, backend_spec
from sonarslam.slam.model.motion import gyro_bias_against_heading
from sonarslam.sonar.beam import SonarBeam
from sonarslam.sonar.store import sector_beam_count

__all__ = [
    "EXTRACTOR_PRESETS",
    "SCAN_PRESETS",
    "RunConfig",
    "preset_for",
    "extractor_config",
    "extractor_preset",
    "pool_preset",
    "map_min_intensity",
    "backend_config",
    "run_config",
    "parse_value",
    "parse_settings",
    "apply_overrides",
    "split_settings",
    "check_settings",
]

_DEG = math.pi / 180.0

#: The marina keyframes (datasets/marina/README.md): Miniking, 1.8 deg step, 0.1 m bins, 50 m
#: range, 3 deg beam; beams are 0/255 masks (a third party's threshold, first 10 bins dropped),
#: with runs of returns metres thick. The first return of each run votes and the line is
#: the least-squares fit through those leading edges ("fit": the wall's face; the paper's
#: overlap-ratio ellipse's centre sits inside the echo band, docs/research/results.md, "Line features on the
#: marina"); the fit's covariance describes the echoes' own noise, the rest of a line's error is
#: the dataset's calibrated systematic error (``[noise] line_sigma_*``, sonarslam calibrate
#: --line-noise) added to it; a 360 deg sector gives longer segments; the odometry's uncertainty
#: over the sector is added (it grows when the DVL degrades).
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
    covariance_method="fit",
    pose_uncertainty=True,
)

#: Extractor presets by name (module docstring).
EXTRACTOR_PRESETS: dict[str, ExtractorConfig] = {
    "default": ExtractorConfig(),
    "marina": _MARINA,
    # the same over a 180 deg sector and 10 votes without the odometry's uncertainty: more,
    # shorter lines whose covariance describes the sonar's own noise only
    "marina-fit": _MARINA.replace(sector_deg=180.0, min_votes=10, pose_uncertainty=False),
    # the paper's overlap-ratio ellipse and its centre (docs/research/results.md: why the closed loops
    # take the fit instead)
    "marina-seed": _MARINA.replace(covariance_method="seed"),
}


#: Scan matcher presets by the same names (:func:`preset_for`): the systematic error of a
#: registration beyond its Hessian (``floor_sigma_m``, ``floor_sigma_deg``). ``default`` (raw
#: beams): measured on the simulator against its truth (``benchmarks/marina_registration.py
#: --source DIR``: NEES of revisits in their band); ``marina`` (thresholded keyframes): the
#: scatter of consecutive registrations about dead reckoning's relative pose, GPS-free
#: (docs/scan-matching.md).
SCAN_PRESETS: dict[str, ScanConfig] = {
    "default": ScanConfig(),
    "marina": ScanConfig(floor_sigma_m=0.5, floor_sigma_deg=1.0),
    "marina-fit": ScanConfig(floor_sigma_m=0.5, floor_sigma_deg=1.0),
}


def preset_for(beams: Sequence[SonarBeam]) -> str:
    """``"marina"`` for thresholded beams (0/255 masks, as the marina keyframes), else
    ``"default"`` (raw intensities)."""
    if isinstance(beams, BeamSeries):  # one kind of beam by construction
        return "marina" if len(beams) and beams.thresholded else "default"
    return "marina" if beams and all(b.thresholded for b in beams) else "default"


#: The tables of a dataset's sonarslam.toml (datasets/config.py), told apart from a settings file.
_DATASET_TABLES = {"sonar", "mounting", "noise", "keyframes", "motion", "gates"}


def _read_table(path: str | Path, table: str) -> tuple[dict[str, Any], str]:
    """The ``[table]`` of a TOML file (or its top level when it has none) and the file's text;
    DataError for a file that cannot be read, is not UTF-8 or not TOML, or whose ``[table]``
    is no table."""
    p = Path(path)
    data, text = read_toml(p)
    dataset_tables = sorted(set(data) & _DATASET_TABLES)
    if table not in data and dataset_tables:
        raise DataError(
            p,
            toml_line(text, "", dataset_tables[0]),
            f"[{dataset_tables[0]}] is a table of a dataset's sonarslam.toml (run --config takes"
            f" those); this file gives [{table}] settings, in an [{table}] table or at the top"
            " level",
        )
    inner = data.get(table, data)
    if not isinstance(inner, dict):
        raise DataError(p, toml_line(text, "", table), f"[{table}] must be a table, got {inner!r}")
    return inner, text


def noise_settings(noise: NoiseConfig | None) -> tuple[dict[str, Any], dict[str, Any]]:
    """``(extractor fields, back-end fields)`` a dataset's ``[noise]`` calibration sets."""
    if noise is None:
        return {}, {}
    ext = {
        "line_sigma_rho_m": noise.line_sigma_rho_m,
        "line_sigma_theta_rad": math.radians(noise.line_sigma_theta_deg),
    }
    return ext, {"noise": noise}


def extractor_config(
    preset: str,
    config_path: str | Path | None = None,
    overrides: dict[str, Any] | None = None,
    noise: NoiseConfig | None = None,
) -> ExtractorConfig:
    """A preset, with a dataset's ``noise`` calibration (:func:`noise_settings`), the fields of a
    TOML file (``[extractor]`` table or top level) and then ``overrides`` (dotted names,
    :func:`apply_overrides`) over it.

    Raises SettingError for an unknown preset or a wrong override, DataError for a wrong
    file or a wrong value in it (naming the file and the key).
    """
    if preset not in EXTRACTOR_PRESETS:
        raise SettingError(
            "extractor preset", f"must be one of {sorted(EXTRACTOR_PRESETS)}, got {preset!r}"
        )
    config = EXTRACTOR_PRESETS[preset].replace(**noise_settings(noise)[0])
    if config_path is not None:
        data, text = _read_table(config_path, "extractor")
        try:
            config = replace_checked(config, data, prefix="[extractor] ", parse_strings=False)
        except SettingError as exc:
            keys = exc.key.replace("[extractor] ", "").split(", ")
            table = "extractor" if toml_line(text, "extractor") is not None else ""
            line = toml_line(text, table, keys[0].split(".")[0]) if len(keys) == 1 else None
            raise DataError(config_path, line, str(exc)) from None
    return apply_overrides(config, overrides or {}, prefix="extractor.")


def extractor_preset(source: str | Dataset) -> ExtractorConfig:
    """The extractor's settings for the front end alone.

    Parameters
    ----------
    source : str or Dataset
        A preset's name (:data:`EXTRACTOR_PRESETS`: ``"default"`` for raw intensity beams,
        ``"marina"`` for thresholded keyframes, ...), or a dataset: the preset of its beams
        (:func:`preset_for`) with its ``[noise]`` calibration, what ``sonarslam run`` extracts
        with.
    """
    if isinstance(source, str):
        return extractor_config(source)
    return extractor_config(preset_for(source.beams), noise=source.config.noise)


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
    (:func:`noise_settings`) and ``overrides`` (dotted names) over it.

    Raises SettingError for a ``noise.<key>`` no back end reads (not in
    :data:`sonarslam.slam.backends.base.BACKEND_NOISE_KEYS`): it goes in ``[noise]``."""
    for key in overrides or {}:
        head, _, field = key.partition(".")
        if head == "noise" and field and field not in BACKEND_NOISE_KEYS:
            raise SettingError(
                f"{name}.{key}",
                f"the back end does not read it (it reads noise.{{{', '.join(BACKEND_NOISE_KEYS)}}});"
                f" the motion model and the start pose take {field} from the dataset's [noise]:"
                " give it in a --config file",
            )
    defaults = backend_spec(name).config_type(**noise_settings(noise)[1])
    return apply_overrides(defaults, overrides or {}, prefix=f"{name}.")


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
    dataset : str or None
        The root of the dataset :meth:`for_dataset` made it for: run on another whose preset
        or ``[noise]`` differ from this configuration's, it is refused
        (:func:`sonarslam.slam.run.run.run_backend`, naming both). None: tied to no dataset.
    """

    preset: str
    extractor: ExtractorConfig
    backend: BackendConfig
    settings: dict[str, Any]
    scans: ScanConfig = ScanConfig()
    #: not a setting: left out of comparisons and of the settings' digest (provenance)
    dataset: str | None = field(default=None, compare=False)

    @classmethod
    def for_dataset(cls, dataset: Dataset, backend: str) -> RunConfig:
        """What ``sonarslam run`` uses on this dataset with no settings: the extractor preset of
        its beams and back end ``backend``'s defaults, both with the dataset's ``[noise]``.
        Change it with :func:`dataclasses.replace` and give it to
        :func:`sonarslam.slam.run.run.run_backend` (``config=``), on this dataset (``dataset``:
        another with another preset or ``[noise]`` is refused)."""
        config = run_config(dataset.beams, backend, None, dataset.config.noise)
        return replace(config, dataset=str(dataset.root))


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
    scans, rest = _scan_settings(given)
    ext, own = split_settings(rest, backend)
    preset = preset_for(beams)
    return RunConfig(
        preset,
        extractor_config(preset, overrides=ext, noise=noise),
        backend_config(backend, own, noise),
        given,
        apply_overrides(SCAN_PRESETS[preset], scans, prefix="scans."),
    )


#: A gyro bias measured against the AHRS heading's change beyond this (deg/s, and beyond 5
#: standard errors) is one a back end without a gyro-bias state must not integrate.
GYRO_BIAS_LIMIT_DEG_PER_S = 0.05


def check_combination(dataset: Dataset, backend: str) -> None:
    """Refuse, before any work, a dataset setting that a back end would silently get wrong.

    The factor graph has no gyro-bias state (the EKF has, :mod:`sonarslam.slam.backends.ekf`): with the
    gyro's rate and a walking AHRS bias, a gyro bias is taken for the walk and the heading
    spins away (docs/design-decisions.md). Refused when the data
    show such a bias (:func:`sonarslam.slam.model.motion.gyro_bias_against_heading`, GPS-free); an
    unbiased gyro (the simulated drift world's) is fine.
    """
    cfg = dataset.config
    if not (
        backend == "isam2"
        and cfg.yaw_rate_source == "gyro"
        and cfg.noise.ahrs_bias_walk_deg_per_sqrt_s > 0.0
    ):
        return
    bias, se = gyro_bias_against_heading(dataset.attitude)
    deg = math.degrees(bias)
    if abs(deg) > GYRO_BIAS_LIMIT_DEG_PER_S and abs(bias) > 5.0 * se:
        raise SettingError(
            "[motion] yaw_rate_source",
            f"'gyro' with [noise] ahrs_bias_walk_deg_per_sqrt_s > 0 is refused for isam2: the"
            f" gyro reads {deg:+.3f} deg/s off the AHRS heading's change and isam2 has no"
            " gyro-bias state, so the bias would be taken for the AHRS bias's walk (use the"
            " ekf, which estimates it, or yaw_rate_source = 'heading')",
        )


_ALIASES = {"association": "association.method", "offline": "offline.enabled"}
#: Back-end settings that moved or were renamed, with their new names: an old one is a
#: SettingError naming the new one (not an alias: one name per setting).
RENAMED_SETTINGS = {
    "ahrs_white_sigma_deg": "noise.ahrs_white_sigma_deg",
    "ahrs_bias_sigma_deg": "noise.ahrs_bias_sigma_deg",
    "ahrs_bias_walk_deg_per_sqrt_s": "noise.ahrs_bias_walk_deg_per_sqrt_s",
    "gyro_sigma_radps": "noise.gyro_sigma_rad_per_s",
    "dvl_scale_sigma": "noise.dvl_scale_sigma",
}

#: A setting's value as typed on the command line (:func:`sonarslam.settings.parse_text`).
parse_value = parse_text


def parse_settings(specs: Iterable[str]) -> dict[str, Any]:
    """``{"ekf.extent_margin_m": 10}`` from ``["ekf.extent_margin_m=10"]``; the values are
    checked against their fields when applied (:func:`apply_overrides`)."""
    out: dict[str, Any] = {}
    for spec in specs:
        name, sep, value = spec.partition("=")
        name = name.strip()
        if not sep or "." not in name or not value.strip():
            raise SettingError("--set", f"expected SCOPE.FIELD=VALUE, got {spec!r}")
        out[name] = parse_value(value)
    return out


def apply_overrides(config: Any, overrides: dict[str, Any], prefix: str = "") -> Any:
    """``config`` with dotted fields (``"association.method"``, aliases too) replaced, each
    value checked against its field (:func:`sonarslam.settings.replace_checked`); ``prefix``
    names the scope in messages. Raises SettingError."""
    for name in overrides:
        if name in RENAMED_SETTINGS and isinstance(config, BackendConfig):
            new = f"{prefix}{RENAMED_SETTINGS[name]}"
            raise SettingError(f"{prefix}{name}", f"was renamed {new} (the dataset's [noise])")
    resolved = {_ALIASES.get(name, name): value for name, value in overrides.items()}
    return replace_checked(config, resolved, prefix=prefix)


def split_settings(params: dict[str, Any], backend: str) -> tuple[dict[str, Any], dict[str, Any]]:
    """``(extractor settings, back-end settings)`` of ``params`` for ``backend``; a setting of
    another back end's scope, or of no scope at all, is a SettingError naming it (and the
    scopes, for the latter)."""
    ext: dict[str, Any] = {}
    own: dict[str, Any] = {}
    for name, value in params.items():
        scope, _, rest = name.partition(".")
        if scope == "extractor":
            ext[rest] = value
        elif scope == backend:
            own[rest] = value
        elif scope in BACKENDS:
            raise SettingError(name, f"does not apply to back end {backend!r}")
        else:
            scopes = sorted({"extractor", "scans", *BACKENDS})
            raise SettingError(name, f"no such scope {scope!r}; the scopes are {scopes}")
    return ext, own


def _scan_settings(settings: dict[str, Any]) -> tuple[dict[str, Any], dict[str, Any]]:
    """``(scan matcher settings without their scope, the others)``."""
    scans = {k.partition(".")[2]: v for k, v in settings.items() if k.startswith("scans.")}
    return scans, {k: v for k, v in settings.items() if not k.startswith("scans.")}


def check_settings(backend: str, settings: dict[str, Any]) -> None:
    """Check settings before anything is read or run: their scope, fields, types and ranges
    over the default configurations (with the preset the beams choose, :func:`run_config`
    checks them again); ``scans.*`` for the back ends that take scans. Raises SettingError."""
    scans, rest = _scan_settings(settings)
    ext, own = split_settings(rest, backend)
    extractor_config("default", overrides=ext)
    config = backend_config(backend, own)
    if scans:
        if "scans" not in config.constraint_kinds:
            raise SettingError(
                next(iter(f"scans.{k}" for k in scans)),
                f"back end {backend!r} takes no scans with constraints {config.constraints!r}",
            )
        apply_overrides(SCAN_PRESETS["default"], scans, prefix="scans.")
