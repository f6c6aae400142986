"""The settings the documentation shows are the code's: every TOML block of README.md and
docs/**/*.md, and the ``sonarslam.toml`` example of :mod:`sonarslam.datasets.config`, loads through
the real loader; that example names every key of the file; every ``[table] key`` and every
``--set SCOPE.FIELD`` the docs mention exists."""

from __future__ import annotations

import dataclasses
import re
import textwrap
import tomllib
from pathlib import Path

import pytest

import sonarslam.datasets.config as dataset_config
from sonarslam.datasets.config import MARINA_CONFIG, config_tables, load_dataset_config
from sonarslam.datasets.navlog import navlog_settings
from sonarslam.datasets.ping360 import ping360_settings
from sonarslam.features.config import ExtractorConfig
from sonarslam.features.scans import ScanConfig
from sonarslam.settings import field_types
from sonarslam.slam.backends.registry import BACKENDS

ROOT = Path(__file__).resolve().parent.parent
DOCS = [ROOT / "README.md", *sorted((ROOT / "docs").rglob("*.md"))]
#: Every key of ``sonarslam.toml`` by table, as the code writes them.
SCHEMA = {table: set(keys) for table, keys in config_tables(MARINA_CONFIG).items()}


def _markdown_blocks() -> list[tuple[str, str]]:
    """``(where, text)`` of every fenced TOML block of the docs."""
    out = []
    for path in DOCS:
        text = path.read_text(encoding="utf-8")
        for found in re.finditer(r"^```toml\n(.*?)^```", text, re.S | re.M):
            line = text[: found.start()].count("\n") + 1
            out.append((f"{path.relative_to(ROOT)}:{line}", found.group(1)))
    return out


def _docstring_example() -> str:
    """The indented ``sonarslam.toml`` example of the dataset configuration's docstring."""
    doc = dataset_config.__doc__ or ""
    block = doc.split("::\n", 1)[1].split("\nEvery value is checked", 1)[0]
    return textwrap.dedent(block)


BLOCKS = [*_markdown_blocks(), ("datasets/config.py docstring", _docstring_example())]


def test_the_docs_hold_toml_examples():
    assert len(BLOCKS) >= 2
    assert "[noise]" in BLOCKS[-1][1] and "[gates]" in BLOCKS[-1][1]


@pytest.mark.parametrize("where,text", BLOCKS, ids=[w for w, _ in BLOCKS])
def test_every_toml_example_loads_through_the_loader(where: str, text: str, tmp_path: Path):
    path = tmp_path / "sonarslam.toml"
    path.write_text(text, encoding="utf-8")
    config = load_dataset_config(path)  # a DataError names the file, line and key
    written = tomllib.loads(text)
    tables = config_tables(config)
    if "ping360" in written:  # a Ping Viewer log's own table, read by its own loader
        ping = ping360_settings(path)
        for key, value in written.pop("ping360").items():
            got = getattr(ping, key)
            if key == "nav":  # the files resolved against the folder; a name or a list
                got = [Path(n).name for n in got]
                value = [value] if isinstance(value, str) else value
            assert got == value, f"{where}: [ping360] {key}"
    if "navlog" in written:  # a navigation log's own table, read by its own loader
        navlog = navlog_settings(path)
        for key, value in written.pop("navlog").items():
            assert getattr(navlog, key) == value, f"{where}: [navlog] {key}"
    for table, key, value in _keys(written):
        if isinstance(value, float | int) and not isinstance(value, bool):
            assert tables[table][key] == pytest.approx(value), f"{where}: [{table}] {key}"


def _keys(data: dict, prefix: str = "") -> list[tuple[str, str, object]]:
    out = []
    for name, value in data.items():
        full = f"{prefix}{name}"
        if isinstance(value, dict):
            out += _keys(value, f"{full}.")
        else:
            out.append((prefix.rstrip("."), name, value))
    return out


def test_the_docstring_example_names_every_key():
    """Each table of ``sonarslam.toml`` and, but for the mountings shown once in full, each of
    its keys: a new setting cannot go undocumented there."""
    written = tomllib.loads(_docstring_example())
    shown: dict[str, set[str]] = {}
    for table, key, _ in _keys(written):
        shown.setdefault(table, set()).add(key)
    assert set(shown) == set(SCHEMA)
    for table, keys in SCHEMA.items():
        if table.startswith("mounting.") and table != "mounting.sonar":
            assert shown[table] <= keys
        else:
            assert shown[table] == keys, f"[{table}] misses {sorted(keys - shown[table])}"


_TABLE_KEY = re.compile(r"`\[((?:mounting\.)?[a-z]+)\](?: |` `)([a-z_]+)")
_SETTING = re.compile(
    r"(?:`|--set |--grid |\")((?:ekf|isam2|extractor|scans)(?:\.[a-z_0-9]+)+)[`=\"]"
)


def _mentions(pattern: re.Pattern[str]) -> list[tuple[str, tuple[str, ...]]]:
    out = []
    for path in DOCS:
        for number, line in enumerate(path.read_text(encoding="utf-8").splitlines(), start=1):
            for found in pattern.finditer(line):
                out.append((f"{path.relative_to(ROOT)}:{number}", found.groups()))
    return out


def test_every_file_key_the_docs_name_exists():
    mentions = [(w, g) for w, g in _mentions(_TABLE_KEY) if g[0] in SCHEMA]
    assert len(mentions) >= 10
    for where, (table, key) in mentions:
        assert key in SCHEMA[table], f"{where}: [{table}] {key} is no key of sonarslam.toml"


def _resolve(name: str) -> None:
    scope, *path = name.split(".")
    configs = {"extractor": ExtractorConfig, "scans": ScanConfig}
    cls: object = configs.get(scope) or BACKENDS[scope].config_type
    for part in path:
        assert dataclasses.is_dataclass(cls), f"{name}: {part} is below a value"
        types = field_types(cls)  # type: ignore[arg-type]
        assert part in types, f"{name}: no field {part} of {cls.__name__}"  # type: ignore[union-attr]
        cls = types[part]


def test_every_run_setting_the_docs_name_exists():
    files = (".tum", ".png", ".py", ".json", ".jsonl", ".npz", ".toml", ".g2o")
    mentions = [(w, g) for w, g in _mentions(_SETTING) if not g[0].endswith(files)]
    assert len(mentions) >= 10
    for where, (name,) in mentions:
        try:
            _resolve(name)
        except AssertionError as exc:
            raise AssertionError(f"{where}: {exc}") from None
