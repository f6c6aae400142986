"""Errors a new user meets first: each names the file and line (or the option) and what is
allowed there."""

from __future__ import annotations

import shutil
from collections.abc import Callable
from pathlib import Path

import pytest

from sonarslam.slam.cli.main import main


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
