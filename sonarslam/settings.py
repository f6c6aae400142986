"""Typed settings: every value from a file or the command line checked against the frozen
dataclass it sets, by one mechanism.

This module belongs to no layer: every layer of :mod:`sonarslam` may import it and it imports
none of them (``tests/test_layers.py``).

``sonarslam.toml`` and ``run --config`` (:func:`sonarslam.datasets.config.load_dataset_config`),
``extract --config``, ``run --set SCOPE.FIELD=VALUE`` and the sweep's grid
(:mod:`sonarslam.slam.run.presets`) all end in :func:`replace_checked`: each dotted name must be a field
of the dataclass (nested dataclasses by dots); its value must have the field's annotated type
(:func:`coerce`: a whole number for an ``int``, a finite number for a ``float``, ``true`` /
``false`` for a ``bool``, a string for a ``str``, ``None`` only where the field allows it, a
table for a nested dataclass); then the dataclass is built, and its ``__post_init__`` checks
the ranges and choices written in its fields' metadata (:func:`bounded`, :func:`one_of`,
:func:`check_fields`). Anything wrong is a :class:`SettingError` naming the key; a file's loader
(:mod:`sonarslam.datasets.toml`) turns it into a :class:`sonarslam.datasets.errors.DataError`
naming the file and line too.

Text from the command line is parsed by the same grammar as the logs' numbers
(:data:`NUMBER`): ``nan``, ``inf``, ``1_000`` or ``0x10`` are not numbers.
"""

from __future__ import annotations

import dataclasses
import math
import re
import types
import typing
from collections.abc import Mapping
from functools import cache
from typing import Any, TypeVar

__all__ = [
    "NUMBER",
    "SettingError",
    "parse_text",
    "coerce",
    "field_types",
    "replace_checked",
    "Range",
    "bounded",
    "one_of",
    "check_fields",
]

#: The grammar of a number in every text input: the logs (:mod:`sonarslam.datasets.logfile`)
#: and numbers given on the command line.
NUMBER = r"[+-]?(?:[0-9]+(?:\.[0-9]*)?|\.[0-9]+)(?:[eE][+-]?[0-9]+)?"
_NUMBER_RE = re.compile(NUMBER)
_INT_RE = re.compile(r"[+-]?[0-9]+")
_NONE_TEXT = ("none", "null")
#: Whole numbers beyond this are no setting of this project (counts, cells, iterations).
MAX_INT = 10**9


def _check_within(
    name: str,
    value: float,
    low: float,
    high: float,
    low_open: bool = False,
    high_open: bool = False,
) -> None:
    """ValueError unless ``low <= value <= high`` (``low < value`` when ``low_open``,
    ``value < high`` when ``high_open``), in the words :func:`replace_checked` reports with the
    key."""
    ok = (value > low if low_open else value >= low) and (
        value < high if high_open else value <= high
    )
    if not ok:
        lb, rb = "(" if low_open else "[", ")" if high_open else "]"
        raise ValueError(f"{name} must be in {lb}{low:g}, {high:g}{rb}, got {value!r}")


_T = TypeVar("_T")


@dataclasses.dataclass(frozen=True)
class Range:
    """The values a numeric setting takes: ``[low, high]``, open at an end when said."""

    low: float
    high: float
    low_open: bool = False
    high_open: bool = False


def bounded(
    default: _T, low: float, high: float, *, low_open: bool = False, high_open: bool = False
) -> _T:
    """A dataclass field with its default and its range in the field's metadata
    (:func:`check_fields` checks it; None always passes)."""
    r = Range(low, high, low_open, high_open)
    return dataclasses.field(default=default, metadata={"range": r})


def one_of(default: _T, *choices: object) -> _T:
    """A dataclass field with its default and the values it may take in its metadata
    (:func:`check_fields`)."""
    return dataclasses.field(default=default, metadata={"choices": choices})


def check_fields(obj: Any) -> None:
    """The one check of a configuration dataclass's fields, for its ``__post_init__``: each
    field's range (:func:`bounded`; every element of a tuple) and choices (:func:`one_of`), in
    the words :func:`replace_checked` reports with the key. ValueError naming the first field
    out of them. What ties two fields together (``max_range_m > min_range_m``) the class checks
    after this, naming the field it refuses."""
    for f in dataclasses.fields(obj):
        value = getattr(obj, f.name)
        r = f.metadata.get("range")
        if r is not None and value is not None:
            for v in value if isinstance(value, tuple) else (value,):
                _check_within(f.name, v, r.low, r.high, r.low_open, r.high_open)
        choices = f.metadata.get("choices")
        if choices is not None and value not in choices:
            said = ", ".join(_choice(c) for c in choices)
            raise ValueError(f"{f.name} must be one of {said}, got {_choice(value)}")


def _choice(value: object) -> str:
    """A choice as it is typed: None as ``'none'`` (:func:`parse_text`; a TOML file's string)."""
    return repr("none") if value is None else repr(value)


class SettingError(ValueError):
    """A setting that cannot be used. ``key`` names it (``"extractor.min_votes"``,
    ``"[sonar] step_deg"``)."""

    def __init__(self, key: str, message: str) -> None:
        self.key = key
        self.message = message
        super().__init__(f"{key}: {message}")

    def __reduce__(self) -> tuple[type[SettingError], tuple[str, str]]:
        # pickled with its two arguments (a process pool's worker raising it: the default
        # pickles the one joined message and cannot build it again)
        return (type(self), (self.key, self.message))


def parse_text(text: str) -> Any:
    """A value typed on the command line, by its look: ``true``/``false``, ``none``/``null``,
    a whole number, a number (:data:`NUMBER`), else the text itself.

    :func:`coerce` then checks it against the field it sets (``"10"`` is fine for a float).
    """
    t = text.strip()
    low = t.lower()
    if low in ("true", "false"):
        return low == "true"
    if low in _NONE_TEXT:
        return None
    if _INT_RE.fullmatch(t):
        return int(t)
    if _NUMBER_RE.fullmatch(t):
        return float(t)
    return t


def _describe(value: Any) -> str:
    return f"{value!r} ({type(value).__name__})"


def _number(value: Any, key: str) -> float:
    if isinstance(value, str):
        value = parse_text(value)
    if isinstance(value, str):
        raise SettingError(key, f"must be a finite number, got {value!r}")
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise SettingError(key, f"must be a number, got {_describe(value)}")
    if isinstance(value, int) and abs(value) > MAX_INT:
        raise SettingError(key, f"must be at most {MAX_INT:.0e} in size, got {value!r}")
    if not math.isfinite(value):
        raise SettingError(key, f"must be a finite number, got {value!r}")
    return float(value)


def coerce(annotation: Any, value: Any, key: str, parse_strings: bool = True) -> Any:
    """``value`` as the type ``annotation`` of a dataclass field, or :class:`SettingError`.

    Accepted: for ``float`` a finite number (an ``int`` too); for ``int`` a whole number
    (``500.0`` too, ``1.5`` not) of at most :data:`MAX_INT`; for ``bool`` a boolean; for
    ``str`` a string; for ``X | None`` also ``None``; for ``tuple[X, ...]`` a list of that
    length. Strings are parsed first (:func:`parse_text`, command-line values) unless the
    field is a string; with ``parse_strings=False`` (a typed file: TOML) a string is taken
    only by a string field (and "none" by an optional one: TOML has no null).
    """
    if not parse_strings and isinstance(value, str):
        if not _takes_text(annotation):
            raise SettingError(key, f"must be {_expected(annotation)}, got the string {value!r}")
    origin, args = typing.get_origin(annotation), typing.get_args(annotation)
    if origin in (typing.Union, types.UnionType):
        options = [a for a in args if a is not type(None)]
        if type(None) in args and (
            value is None or (isinstance(value, str) and value.strip().lower() in _NONE_TEXT)
        ):
            return None
        if len(options) == 1:
            return coerce(options[0], value, key, parse_strings)
        errors = []
        for option in options:
            try:
                return coerce(option, value, key, parse_strings)
            except SettingError as exc:
                errors.append(exc.message)
        raise SettingError(key, " or ".join(errors))
    if value is None:
        raise SettingError(key, "must be set (None is not allowed here)")
    if annotation is str:
        if not isinstance(value, str):
            raise SettingError(key, f"must be a string, got {_describe(value)}")
        return value
    if annotation is bool:
        if isinstance(value, str) and value.strip().lower() in ("true", "false"):
            return value.strip().lower() == "true"
        if not isinstance(value, bool):
            raise SettingError(key, f"must be true or false, got {_describe(value)}")
        return value
    if annotation is float:
        return _number(value, key)
    if annotation is int:
        number = _number(value, key)
        if number != math.floor(number):
            raise SettingError(key, f"must be a whole number, got {value!r}")
        return int(number)
    if origin is tuple:
        if isinstance(value, str):
            value = value.split(",")
        if not isinstance(value, list | tuple) or len(value) != len(args):
            raise SettingError(key, f"must be a list of {len(args)}, got {_describe(value)}")
        return tuple(
            coerce(a, v, f"{key}[{i}]", parse_strings)
            for i, (a, v) in enumerate(zip(args, value, strict=True))
        )
    raise SettingError(key, f"cannot be set (a {annotation!r})")


def _takes_text(annotation: Any) -> bool:
    """A string field, or an optional one (whose "none" a typed file must write as text)."""
    args = typing.get_args(annotation)
    return annotation is str or str in args or type(None) in args


def _expected(annotation: Any) -> str:
    names = {float: "a number", int: "a whole number", bool: "true or false"}
    if annotation in names:
        return names[annotation]
    return "a list" if typing.get_origin(annotation) is tuple else f"a {annotation!r}"


@cache
def field_types(cls: type) -> dict[str, Any]:
    """The resolved annotations of a dataclass's fields."""
    hints = typing.get_type_hints(cls)
    return {f.name: hints[f.name] for f in dataclasses.fields(cls)}


def _tree(changes: Mapping[str, Any], prefix: str) -> dict[str, Any]:
    """``{"a.b": 1, "a.c": 2}`` -> ``{"a": {"b": ("a.b", 1), "c": ("a.c", 2)}}`` (the full keys
    with ``prefix``)."""
    tree: dict[str, Any] = {}
    for short, value in changes.items():
        name = f"{prefix}{short}"
        parts = short.split(".")
        node = tree
        for part in parts[:-1]:
            child = node.setdefault(part, {})
            if not isinstance(child, dict):
                raise SettingError(name, f"{part!r} is set both whole and by its fields")
            node = child
        if isinstance(node.get(parts[-1]), dict):
            raise SettingError(name, "is a table of settings, not one value")
        node[parts[-1]] = (name, value)
    return tree


def _apply(obj: Any, tree: dict[str, Any], prefix: str, parse_strings: bool = True) -> Any:
    cls: type = type(obj)
    types_ = field_types(cls)
    kwargs: dict[str, Any] = {}
    keys: list[str] = []
    for name, node in tree.items():
        key = f"{prefix}{name}"
        if name not in types_:
            raise SettingError(key, f"unknown field of {cls.__name__}; one of {sorted(types_)}")
        annotation = types_[name]
        is_table = dataclasses.is_dataclass(annotation)
        if isinstance(node, dict):
            if not is_table:
                raise SettingError(key, f"is one value ({annotation}), not a table")
            kwargs[name] = _apply(getattr(obj, name), node, f"{key}.", parse_strings)
            keys.append(key)
            continue
        full_key, value = node
        if is_table:
            raise SettingError(full_key, f"is a table of {annotation.__name__} settings")
        kwargs[name] = coerce(annotation, value, full_key, parse_strings)
        keys.append(full_key)
    try:
        return dataclasses.replace(obj, **kwargs)
    except (ValueError, TypeError) as exc:
        message = str(exc)
        # "min_votes must be >= 1": the key it names alone, and the message after it
        for name, key in zip(kwargs, keys, strict=True):
            stripped = re.sub(rf"^(\w+\.)?{re.escape(name)} ", "", message)
            if stripped != message:
                raise SettingError(key, stripped) from None
        raise SettingError(", ".join(keys), message) from None


def replace_checked(
    obj: Any, changes: Mapping[str, Any], prefix: str = "", parse_strings: bool = True
) -> Any:
    """A frozen dataclass with dotted fields replaced, each checked (module docstring).

    Parameters
    ----------
    obj : dataclass instance
    changes : mapping of str to value
        ``{"association.method": "nn", "min_votes": "12"}``; values typed or text.
    prefix : str
        Put before the names in messages (``"extractor."``).
    parse_strings : bool
        Text values are parsed (command-line values); False for a typed file (TOML), whose
        strings only string fields take (:func:`coerce`).

    Raises
    ------
    SettingError
        An unknown field, a value of the wrong type, non-finite or out of range (the
        dataclass's own checks), naming the key.
    """
    if not changes:
        return obj
    return _apply(obj, _tree(changes, prefix), prefix, parse_strings)
