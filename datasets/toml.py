"""TOML files of settings: read with the file and line of a syntax error, and the line of a
key, so that a setting's error (:class:`sonarslam.settings.SettingError`) can name where it was
written (:class:`sonarslam.datasets.errors.DataError`)."""

from __future__ import annotations

import re
import tomllib
from pathlib import Path
from typing import Any

from sonarslam.datasets.errors import DataError
from sonarslam.datasets.logfile import read_text, split_lines

__all__ = ["read_toml", "toml_line", "toml_file_line"]


def read_toml(path: str | Path) -> tuple[dict[str, Any], str]:
    """A TOML file (UTF-8, :func:`sonarslam.datasets.logfile.read_text`) and its text; a syntax error is
    a :class:`DataError` with its line (the last line when the parser ran out of document)."""
    p = Path(path)
    text = read_text(p, "utf-8")
    try:
        return tomllib.loads(text), text
    except tomllib.TOMLDecodeError as exc:
        found = re.search(r"at line (\d+)", str(exc))
        line = int(found.group(1)) if found else None
        if line is None and "end of document" in str(exc):
            line = max(len(split_lines(text)[0]), 1)
        raise DataError(p, line, f"TOML syntax error: {exc}") from None


_TABLE_HEADER = re.compile(r"\[\s*([^\[\]]+?)\s*\]\s*(?:#.*)?")
_KEY = re.compile(r"\s*\"?([A-Za-z0-9_.-]+)\"?\s*=")


def toml_line(text: str, table: str, key: str | None = None) -> int | None:
    """The physical line of ``key = ...`` in ``[table]`` of a TOML text (``table`` dotted,
    ``""`` for the top level), or of the ``[table]`` header when ``key`` is None; None when not
    written that way (an inline table, a dotted key)."""
    current = ""
    for number, raw in enumerate(split_lines(text)[0], start=1):
        header = _TABLE_HEADER.fullmatch(raw.strip())
        if header is not None:
            current = re.sub(r"\s*\.\s*", ".", header.group(1)).replace('"', "")
            if key is None and current == table:
                return number
            continue
        found = _KEY.match(raw)
        if key is not None and found is not None and current == table and found.group(1) == key:
            return number
    return None


def toml_file_line(path: str | Path, table: str, keys: tuple[str, ...]) -> int | None:
    """The line (:func:`toml_line`) in the TOML file ``path`` of the first of ``keys`` written
    in ``[table]``; None when none is, or the file cannot be read as UTF-8 text."""
    try:
        text = Path(path).read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError):
        return None
    lines = (toml_line(text, table, k) for k in keys)
    return next((n for n in lines if n is not None), None)
