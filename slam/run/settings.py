"""Every setting of a dataset and of its runs, with its unit and where its value comes from
(``sonarslam info``).

* The dataset's settings (``sonarslam.toml``'s keys, :func:`sonarslam.datasets.config.config_tables`): from
  the dataset's own ``sonarslam.toml``, else its ``*_SETUP.log`` (the head) and the marina
  calibration (``datasets.config.MARINA_CONFIG``, docs/research/calibration.md) for the marina's logs,
  neutral defaults for any other; keys a
  ``sonarslam.toml`` leaves out take the neutral defaults of ``DatasetConfig``.
* The run settings (``--set SCOPE.FIELD=VALUE``, :mod:`sonarslam.slam.run.presets`): the extractor preset
  of the dataset's beams, its scan matcher preset and each back end's defaults, with the
  ``--set`` values given over them.

Units are read off the names (``_m``: metres, ``_deg``, ``_rad``, ``_s``, ``_mps``: m/s, ...).
"""

from __future__ import annotations

import dataclasses
import tomllib
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from sonarslam.datasets.config import config_tables
from sonarslam.datasets.source import Dataset
from sonarslam.settings import SettingError
from sonarslam.slam.backends.base import BACKEND_NOISE_KEYS
from sonarslam.slam.backends.registry import BACKENDS
from sonarslam.slam.run.presets import (
    SCAN_PRESETS,
    apply_overrides,
    backend_config,
    extractor_config,
    noise_settings,
    preset_for,
)

__all__ = ["Setting", "unit_of", "dataset_settings", "run_settings", "check_run_settings"]

_UNITS = [
    ("_deg_per_sqrt_s", "deg/sqrt(s)"),
    ("_deg_per_s", "deg/s"),
    ("_mps", "m/s"),
    ("_rad_per_s", "rad/s"),
    ("_m", "m"),
    ("_deg", "deg"),
    ("_rad", "rad"),
    ("_s", "s"),
    ("_ms", "ms"),
    ("_hz", "Hz"),
]
_NAMED_UNITS = {
    "n_bins": "bins",
    "angle_sense": "+1 / -1",
    "scan_direction": "+1 / -1",
    "ahrs_deviation_deg": "deg (B, C)",
}


def unit_of(name: str) -> str:
    """The unit of a setting from its name (``range_sigma_m``: ``m``); ``""`` when it has none
    (counts, ratios, choices)."""
    key = name.rsplit(".", 1)[-1]
    if key in _NAMED_UNITS:
        return _NAMED_UNITS[key]
    for suffix, unit in _UNITS:
        if key.endswith(suffix):
            return unit
    return ""


@dataclass(frozen=True)
class Setting:
    """One setting: its name (``[table] key`` or ``SCOPE.FIELD``), value, unit and source."""

    name: str
    value: Any
    unit: str
    source: str


def _file_keys(root: Path) -> tuple[Path | None, dict[str, set[str]]]:
    """The ``sonarslam.toml`` of a dataset (in its directory or one below; beside a bag or a
    log file) and the keys it sets, by table."""
    if root.is_dir():
        found = sorted(set(root.glob("sonarslam.toml")) | set(root.glob("*/sonarslam.toml")))
    else:
        found = sorted(root.parent.glob("sonarslam.toml"))
    if not found:
        return None, {}
    return found[0], _toml_keys(found[0])


def _toml_keys(path: Path) -> dict[str, set[str]]:
    """The keys a ``sonarslam.toml``-format file sets, by table (``mounting.sonar``)."""
    with open(path, "rb") as f:
        data = tomllib.load(f)
    keys: dict[str, set[str]] = {}
    for table, inner in data.items():
        if table == "mounting" and isinstance(inner, dict):
            for sub, items in inner.items():
                keys[f"mounting.{sub}"] = set(items)
        elif isinstance(inner, dict):
            keys[table] = set(inner)
    return keys


#: The head's keys a Ping Viewer log gives (sonarslam.datasets.ping360) and where from.
_PING360_HEAD_KEYS = {
    "n_bins": "the .bin log (number_of_samples)",
    "bin_size_m": "the .bin log (sample_period, [ping360] speed_of_sound_mps)",
    "step_deg": "the .bin log (median angle change)",
    "beam_width_deg": "the Ping360's datasheet (2 deg)",
}


def dataset_settings(dataset: Dataset, override: str | Path | None = None) -> list[Setting]:
    """The dataset's settings, each with its unit and source (module docstring); the keys of
    ``override`` (the ``sonarslam.toml``-format file the dataset was opened with,
    ``open_dataset(config_override=...)``) name that file."""
    # a bag file or a Ping Viewer .bin: its sonarslam.toml is the one beside it
    folder = dataset.root if dataset.root.is_dir() else dataset.root.parent
    toml, in_file = _file_keys(folder)
    over = _toml_keys(Path(override)) if override is not None else {}
    setup = sorted(folder.glob("*_SETUP.log")) + sorted(folder.glob("*/*_SETUP.log"))
    ping360 = dataset.root.suffix == ".bin"  # its head's keys the file leaves out: the log's
    out = []
    for table, items in config_tables(dataset.config).items():
        mounting_source = items.get("source") if table.startswith("mounting.") else None
        for key, value in items.items():
            if key == "source":
                continue
            if ping360 and table == "sonar" and key in _PING360_HEAD_KEYS:
                if key in ("n_bins", "bin_size_m") or key not in in_file.get(table, set()):
                    source = _PING360_HEAD_KEYS[key]
                else:
                    source = toml.name if toml is not None else ""
            elif toml is not None:
                source = (
                    toml.name if key in in_file.get(table, set()) else "default (DatasetConfig)"
                )
            elif table == "sonar" and key in ("n_bins", "bin_size_m", "step_deg") and setup:
                source = setup[0].name
            elif dataset.calibration.startswith("marina"):
                source = "marina calibration (MARINA_CONFIG)"
            else:  # open_dataset: not the marina, no sonarslam.toml
                source = "neutral default (no sonarslam.toml)"
            if (
                mounting_source
                and mounting_source.startswith("transforms of")
                and table not in in_file
            ):
                source = mounting_source  # a bag's /tf_static, not a neutral default
            elif mounting_source and key == "yaw_deg":
                source += f": {mounting_source}"
            if key in over.get(table, set()):
                source = f"{Path(override or '').name} (--config)"
            out.append(Setting(f"[{table}] {key}", value, unit_of(key), source))
    return out


def _flatten(prefix: str, config: Any) -> list[tuple[str, Any]]:
    out: list[tuple[str, Any]] = []
    for f in dataclasses.fields(config):
        value = getattr(config, f.name)
        if dataclasses.is_dataclass(value) and not isinstance(value, type):
            out += _flatten(f"{prefix}.{f.name}", value)
        else:
            out.append((f"{prefix}.{f.name}", value))
    return out


def _by_scope(settings: dict[str, Any]) -> dict[str, dict[str, Any]]:
    """``settings`` (``SCOPE.FIELD`` -> value) by scope, every scope of :func:`run_settings`
    present. Raises SettingError for another scope."""
    scopes = {"extractor", "scans", *BACKENDS}
    given: dict[str, dict[str, Any]] = {scope: {} for scope in scopes}
    for name, value in settings.items():
        scope, _, field = name.partition(".")
        if scope not in scopes:
            raise SettingError(name, f"no such scope {scope!r}; the scopes are {sorted(scopes)}")
        given[scope][field] = value
    return given


def check_run_settings(settings: dict[str, Any]) -> None:
    """Check ``settings`` (``SCOPE.FIELD`` -> value) over the default configurations before a
    dataset is read: scope, field, type and range (:func:`run_settings` applies them to the
    dataset's presets). Raises SettingError."""
    given = _by_scope(settings)
    extractor_config("default", overrides=given["extractor"])
    apply_overrides(SCAN_PRESETS["default"], given["scans"], prefix="scans.")
    for backend in BACKENDS:
        backend_config(backend, given[backend])


def run_settings(dataset: Dataset, settings: dict[str, Any] | None = None) -> list[Setting]:
    """The extractor preset of the dataset's beams, its scan matcher preset and every back
    end's defaults, by their ``--set`` names (``extractor.min_votes``,
    ``ekf.association.gate_probability``, ``scans.max_range_m``), with ``settings``
    (``SCOPE.FIELD`` -> value, as ``sonarslam run --set``) over them, each checked against its
    field.

    Raises SettingError for a setting of no scope listed here or a wrong field or value.
    """
    given = _by_scope(settings or {})
    preset = preset_for(dataset.beams)
    noise = dataset.config.noise
    from_noise = {f"extractor.{k}" for k in noise_settings(noise)[0]}
    from_noise |= {f"{b}.noise.{k}" for b in BACKENDS for k in BACKEND_NOISE_KEYS}
    # the [noise] keys a back end does not read (BACKEND_NOISE_KEYS) are left out: they act
    # through the dataset's [noise], listed with the dataset's settings
    unread = {f"{b}.noise.{f.name}" for b in BACKENDS for f in dataclasses.fields(noise)}
    unread -= from_noise

    def listed(prefix: str, default: Any, changed: Any, source: str) -> list[Setting]:
        out = []
        for (name, before), (_, value) in zip(
            _flatten(prefix, default), _flatten(prefix, changed), strict=True
        ):
            if name in unread:
                continue
            if value != before or name.partition(".")[2] in given[prefix]:
                where = "--set"
            elif name in from_noise:
                where = "the dataset's [noise] (slam/run/presets.py: noise_settings)"
            else:
                where = source
            out.append(Setting(name, value, unit_of(name), where))
        return out

    out = listed(
        "extractor",
        extractor_config(preset, noise=noise),
        extractor_config(preset, noise=noise, overrides=given["extractor"]),
        f"extractor preset {preset!r} (slam/run/presets.py)",
    )
    scans = SCAN_PRESETS.get(preset, SCAN_PRESETS["default"])
    out += listed(
        "scans",
        scans,
        apply_overrides(scans, given["scans"], prefix="scans."),
        f"scan preset {preset if preset in SCAN_PRESETS else 'default'!r} (constraints with scans)",
    )
    for backend in BACKENDS:
        config = backend_config(backend, noise=noise)
        out += listed(
            backend,
            config,
            backend_config(backend, given[backend], noise=noise),
            f"{type(config).__name__} default",
        )
    return out
