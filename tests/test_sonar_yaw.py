"""The sonar mounting yaw from the map's sharpness (slam.run.calibration.calibrate_sonar_yaw,
``sonarslam calibrate``), against the simulator's true mounting: the yaw found is the truth's,
or the objective is reported flat and the command refuses; never a wrong yaw with exit 0."""

from __future__ import annotations

import math
from collections.abc import Callable
from pathlib import Path

import pytest

from sonarslam.datasets.source import Dataset, open_dataset
from sonarslam.features.geometry import wrap_angle
from sonarslam.slam.cli import calibrate as calibrate_cli
from sonarslam.slam.cli.main import main
from sonarslam.slam.eval.truth import true_sonar
from sonarslam.slam.run.calibration import (
    MIN_YAW_DEPTH,
    MIN_YAW_MARGIN,
    YawSearch,
    calibrate_sonar_yaw,
)
from sonarslam.slam.run.sources import pose_source_by_name
from tests.echoes import shuffled_echoes

#: Tolerance (deg) on the yaw found: the fine grid's step is 0.25 deg, the dead-reckoning
#: heading of a 120 s window errs by about a degree (AHRS bias 2 deg, sigma 0.5 deg).
YAW_TOL_DEG = 3.0


@pytest.fixture(scope="module")
def harbour(simulated: Callable[..., Path]) -> Dataset:
    """300 s of the harbour world (raw intensities with background noise, sonar yaw 180 deg)."""
    return open_dataset(simulated("harbour", 2, 300.0))


@pytest.fixture(scope="module")
def harbour_search(harbour: Dataset) -> YawSearch:
    return calibrate_sonar_yaw(harbour, pose_source_by_name(harbour, "dr"))


def test_sonar_yaw_of_the_harbour_is_the_truth(harbour: Dataset, harbour_search: YawSearch) -> None:
    """Raw beams: the echoes (bins at the extractor's threshold) are scored, not the background
    noise that made the objective flat (30.68 vs 30.75 nats over 360 deg, least at 22 deg)."""
    truth = true_sonar(harbour)[0][2]
    err = math.degrees(abs(wrap_angle(harbour_search.best_yaw_rad - truth)))
    assert err < YAW_TOL_DEG, (math.degrees(harbour_search.best_yaw_rad), math.degrees(truth))
    assert harbour_search.decisive, harbour_search.verdict()
    # seeds 1-4 gave depth 17-30 and margin 12-21 noise units, the shuffled echoes <= 3.1 and
    # <= 1.1, the marina 9.7 and 7.2
    assert harbour_search.depth > 2 * MIN_YAW_DEPTH
    assert harbour_search.margin > 2 * MIN_YAW_MARGIN


def test_sonar_yaw_without_geometry_is_not_decisive(harbour: Dataset) -> None:
    """Echoes shuffled among the beams: the objective is flat and says so."""
    ds = shuffled_echoes(harbour, seed=7)
    search = calibrate_sonar_yaw(ds, pose_source_by_name(ds, "dr"))
    assert not search.decisive, search.verdict()
    assert search.depth < MIN_YAW_DEPTH or search.margin < MIN_YAW_MARGIN


def test_calibrate_cli_yaw_or_refusal(
    harbour: Dataset,
    tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture[str],
) -> None:
    """The command prints the true yaw with exit 0, or refuses (exit 1, one line, nothing
    written) when the objective is flat."""
    out = tmp_path / "sonarslam.toml"
    assert main(["calibrate", str(harbour.root), "--write", str(out)]) == 0
    line = [s for s in capsys.readouterr().out.splitlines() if "sonar mounting yaw" in s][0]
    found = float(line.split("poses: ")[1].split(" deg")[0])
    truth = math.degrees(true_sonar(harbour)[0][2])
    assert abs((found - truth + 180.0) % 360.0 - 180.0) < YAW_TOL_DEG, line
    assert out.is_file()

    flat = shuffled_echoes(harbour, seed=7)
    monkeypatch.setattr(calibrate_cli, "open_dataset", lambda *a, **k: flat)
    refused = tmp_path / "refused.toml"
    assert main(["calibrate", str(harbour.root), "--write", str(refused)]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "too flat to give a sonar yaw" in err[0], err
    assert "nothing written" in err[0]
    # a mirrored sonar flattens the objective too: the refusal names it (issue 32's review)
    assert "[sonar] angle_sense" in err[0]
    assert not refused.exists()
