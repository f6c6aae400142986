"""Packaging: the lock pins every dependency inside pyproject.toml's ranges, the supported
Pythons are declared, the packages ship ``py.typed``, and ``sonarslam --version`` answers."""

from __future__ import annotations

import subprocess
import sys
import tomllib
from pathlib import Path

from packaging.requirements import Requirement
from packaging.utils import canonicalize_name

from sonarslam.slam.cli.main import build_parser

ROOT = Path(__file__).resolve().parents[1]


def _lock() -> dict[str, str]:
    pins = {}
    for line in (ROOT / "requirements.lock").read_text().splitlines():
        if line.strip() and not line.startswith("#"):
            name, sep, ver = line.partition("==")
            assert sep, f"requirements.lock: not an exact pin: {line!r}"
            pins[canonicalize_name(name)] = ver.strip()
    return pins


def test_lock_pins_every_dependency_inside_its_range() -> None:
    """Every dependency and every extra's (the optional ones and the development tools)."""
    project = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    pins = _lock()
    extras = project["optional-dependencies"]
    assert {"sim", "sweep", "dev"} <= set(extras)
    reqs = [*project["dependencies"], *(r for group in extras.values() for r in group)]
    assert len(reqs) >= 20
    for text in reqs:
        req = Requirement(text)
        name = canonicalize_name(req.name)
        if name == "sonarslam":  # dev holds the other extras, so that [dev] installs them all
            assert req.extras == set(extras) - {"dev"}, f"dev holds {req.extras}, not every extra"
            continue
        assert name in pins, f"{req.name} is not in requirements.lock"
        assert req.specifier.contains(pins[name]), (
            f"{req.name}=={pins[name]} outside {req.specifier}"
        )


def test_supported_pythons_declared() -> None:
    project = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    assert project["requires-python"] == ">=3.11,<3.14"
    for minor in (11, 12, 13):
        assert f"Programming Language :: Python :: 3.{minor}" in project["classifiers"]
    assert sys.version_info[:2] >= (3, 11)


def test_packages_are_typed() -> None:
    for package in ("sonarslam", "sonar", "features", "slam", "datasets"):
        assert (ROOT / package / "py.typed").is_file(), package


def test_license_file_matches_the_declared_license() -> None:
    """pyproject.toml declares BSD-3-Clause; the LICENSE file beside it is that license's text."""
    project = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    assert project["license"] == {"text": "BSD-3-Clause"}
    assert "License :: OSI Approved :: BSD License" in project["classifiers"]
    text = (ROOT / "LICENSE").read_text()
    assert text.startswith("BSD 3-Clause License")
    assert "Neither the name of the copyright holder" in text  # the third clause


def _fake_python(path: Path, version: str) -> Path:
    """An executable that answers the Makefile's version question with ``version`` and, as
    ``-m venv DIR``, makes a venv whose python answers the same."""
    path.write_text(
        "#!/bin/sh\n"
        f'if [ "$1" = "-m" ]; then mkdir -p "$3/bin" && cp "$0" "$3/bin/python"; exit 0; fi\n'
        f'echo "{version}"\n'
    )
    path.chmod(0o755)
    return path


def test_venv_is_rebuilt_only_when_the_python_version_changes(tmp_path: Path) -> None:
    """The same version at another path (pyenv's 3.11.7 and /usr/bin's 3.11.2: both cp311)
    keeps .venv; another minor version rebuilds it."""
    venv = tmp_path / ".venv"

    def make(python: Path) -> str:
        return subprocess.run(
            ["make", "-s", "-f", str(ROOT / "Makefile"), f"VENV={venv}", f"PYTHON={python}",
             f"{venv}/.python"],
            cwd=ROOT, capture_output=True, text=True, check=True,
        ).stdout  # fmt: skip

    make(_fake_python(tmp_path / "py_a", "cpython 3.11"))
    assert (venv / ".python").read_text() == "cpython 3.11\n"
    (venv / "kept").touch()
    assert make(_fake_python(tmp_path / "py_b", "cpython 3.11")) == ""  # another path: kept
    assert (venv / "kept").is_file()
    printed = make(_fake_python(tmp_path / "py_c", "cpython 3.12"))
    assert "rebuilding it with cpython 3.12" in printed
    assert not (venv / "kept").exists() and (venv / ".python").read_text() == "cpython 3.12\n"


def test_version_flag() -> None:
    out = subprocess.run(
        [sys.executable, "-m", "sonarslam.slam.cli.main", "--version"],
        capture_output=True,
        text=True,
        cwd=ROOT,
        check=True,
    ).stdout
    assert out.startswith("sonarslam ")
    assert build_parser().prog == "sonarslam"
