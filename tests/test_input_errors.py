"""Errors a new user meets first: each names the file and line (or the option) and what is
allowed there; and ``make lint`` checks the project's folders, not a user's scratch files."""

from __future__ import annotations

import re
import shutil
import subprocess
from collections.abc import Callable
from pathlib import Path

import pytest

from sonarslam.datasets.source import open_dataset
from sonarslam.slam.cli.main import main
from sonarslam.slam.run.presets import backend_config, parse_settings

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def bag(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A 30 s simulated pool as an MCAP bag (its sonarslam.toml inside)."""
    out = tmp_path_factory.mktemp("bag") / "rov"
    assert main(["simulate", "pool", "--duration", "30", "--out", str(out), "--bag", "mcap"]) == 0
    return out


def _error(capsys: pytest.CaptureFixture[str]) -> str:
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1, err
    return err[0]


def test_a_mounting_typo_lists_the_mountings(
    simulated: Callable[..., Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    src = tmp_path / "typo"
    shutil.copytree(simulated("harbour", 0, 60.0), src)
    toml = src / "sonarslam.toml"
    text = toml.read_text()
    toml.write_text(text.replace("[mounting.sonar]", "[mounting.sonr]"))
    line = 1 + text.split("\n").index("[mounting.sonar]")
    assert main(["info", str(src)]) == 1
    assert _error(capsys).endswith(
        f"{toml}:{line}: unknown key 'sonr' in [mounting]; allowed: ['ahrs', 'dvl', 'sonar']"
    )


def test_a_bags_malformed_toml_and_a_missing_topics_file_name_file_and_line(
    bag: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    bad = tmp_path / "bad"
    shutil.copytree(bag, bad)
    toml = bad / "sonarslam.toml"
    lines = toml.read_text().splitlines()
    toml.write_text("\n".join([*lines, "[noise]", "dvl_sigma_mps = 0.1", ""]))
    for command in ("info", "run"):
        args = [command, str(bad)] + (["--out", str(tmp_path / "o")] if command == "run" else [])
        assert main(args) == 1
        err = _error(capsys)
        assert f"{toml}:{len(lines) + 1}: TOML syntax error: Cannot declare ('noise',) twice" in err
    missing = tmp_path / "nope.toml"
    for command in ("info", "run"):
        args = [command, str(bag), "--topics", str(missing)]
        args += ["--out", str(tmp_path / "o")] if command == "run" else []
        assert main(args) == 1
        assert _error(capsys).endswith(f"error: {missing}: file not found")


def test_info_first_line_says_what_the_source_is(
    bag: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["info", str(bag)]) == 0
    line = next(x for x in capsys.readouterr().out.splitlines() if x.startswith("rov: "))
    assert line == f"rov: ROS bag at {bag.resolve()}; calibration: {bag / 'sonarslam.toml'}"


def test_lint_checks_the_projects_folders_and_every_tracked_python_file() -> None:
    """``make style`` (ruff, for ``make lint`` and ``make test``) names its folders (a scratch
    file at the clone's top is not linted), and every Python file git tracks lies in one of
    them (or in notebooks/, which ruff excludes)."""
    recipe = re.search(r"^style:.*\n((?:\t.*\n)+)", (ROOT / "Makefile").read_text(), re.M)
    assert recipe is not None
    check = next(x for x in recipe[1].splitlines() if "ruff check" in x)
    assert not re.search(r"ruff check \.(\s|$)", check), check
    dirs = re.search(r"^LINT_DIRS = (.*)$", (ROOT / "Makefile").read_text(), re.M)
    assert dirs is not None
    linted = {*dirs[1].split(), *check.split("ruff check ")[1].split()} - {"$(LINT_DIRS)"}
    if not (ROOT / ".git").exists():
        pytest.skip("not a git clone: no tracked files to compare")
    tracked = subprocess.run(
        ["git", "ls-files", "*.py"], cwd=ROOT, capture_output=True, text=True, check=True
    ).stdout.split()
    outside = [p for p in tracked if p.split("/")[0] not in linted | {"notebooks"}]
    assert not outside, outside


def test_a_setting_of_no_scope_lists_the_scopes(
    simulated: Callable[..., Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """``--set foo.bar=1`` said "does not apply to back end 'isam2'" (a review): the scope is
    unknown, and the scopes are listed; another back end's setting still says so."""
    args = ["run", str(simulated("harbour", 0, 60.0)), "--backend", "isam2"]
    args += ["--out", str(tmp_path / "o"), "--quiet"]
    assert main([*args, "--set", "foo.bar=1"]) == 2
    assert _error(capsys) == (
        "sonarslam run: error: foo.bar: no such scope 'foo'; the scopes are"
        " ['ekf', 'extractor', 'isam2', 'scans']"
    )
    assert main([*args, "--set", "ekf.min_rho_m=2"]) == 2
    assert _error(capsys).endswith("ekf.min_rho_m: does not apply to back end 'isam2'")
    assert not (tmp_path / "o").exists()


def test_a_choice_of_none_is_said_as_typed(
    simulated: Callable[..., Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """The choices of a field that may be None say it 'none', as ``--set`` (and a TOML file)
    spell it, not Python's None (a review)."""
    args = ["run", str(simulated("harbour", 0, 60.0)), "--backend", "isam2"]
    args += ["--out", str(tmp_path / "o"), "--quiet"]
    assert main([*args, "--set", "isam2.offline.noise_scales=some"]) == 2
    assert _error(capsys).endswith(
        "isam2.offline.noise_scales: must be one of 'measurements', 'all', 'none', got 'some'"
    )
    # and 'none' is what --set takes for None
    (value,) = parse_settings(["isam2.offline.noise_scales=none"]).values()
    config = backend_config("isam2", {"offline.noise_scales": value})
    assert config.offline.noise_scales is None  # type: ignore[attr-defined]


def test_a_span_without_a_gps_fix_in_its_navigation_names_span(
    simulated: Callable[..., Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """``--span 0,1`` on the marina said "no GPS fix inside the navigation span" (a review):
    its one fix came before the span's first DVL row. The error names --span."""
    source = simulated("harbour", 0, 60.0)
    d = open_dataset(source)
    assert d.gps is not None
    t0, gps_t, dvl_t = d.nav_span_s[0], d.gps.t, d.dvl.t
    # a fix followed by two DVL rows before the next fix; the span from just before the fix
    # to just after the second row: its navigation starts at the first row, after the fix
    for g, after in zip(gps_t[1:], gps_t[2:], strict=False):
        d1, d2 = dvl_t[dvl_t > g][:2]
        if d2 + 1e-3 < after:
            break
    span = f"{g - 1e-3 - t0:.4f},{d2 + 1e-3 - t0:.4f}"
    args = ["run", str(source), "--span", span, "--out", str(tmp_path / "o"), "--quiet"]
    assert main(args) == 1
    err = _error(capsys)
    assert "--span " in err and "holds no GPS fix inside its navigation" in err
    assert f"both logging, {d1 - t0:.3f}-" in err and "its 1 fix(es) fall outside" in err
