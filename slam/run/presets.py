"""Settings given as ``SCOPE.FIELD=VALUE`` (``sonarslam run --set``, ``sonarslam sweep --grid``).

``SCOPE`` is ``extractor`` (:class:`features.extractor.ExtractorConfig`) or a back end (``ekf``:
:class:`slam.backends.ekf.EkfConfig`, ``isam2``: :class:`slam.backends.isam2.graph.GraphConfig`); ``FIELD`` is a
field of that frozen dataclass, nested by dots (``ekf.association.gate_probability``);
``<backend>.association`` is short for ``<backend>.association.method``.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Iterable, Sequence
from typing import Any

__all__ = ["parse_value", "parse_settings", "apply_overrides", "split_settings"]

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
