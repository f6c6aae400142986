"""The sonar clock offset from the map's sharpness (slam.run.calibration.calibrate_time_offset,
``sonarslam calibrate --time-offset``), against the simulator's clock (the sonar's beams on the
navigation clock, offset 0): a shifted clock is found, or the objective is reported flat and the
command refuses; never a wrong offset with exit 0."""

from __future__ import annotations

import tomllib
from collections.abc import Callable
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from sonarslam.datasets.source import Dataset, open_dataset
from sonarslam.slam.cli import calibrate as calibrate_cli
from sonarslam.slam.cli.main import main
from sonarslam.slam.eval.sharpness import map_entropy, map_entropy_variance
from sonarslam.slam.run.calibration import (
    MIN_CLOCK_DEPTH,
    MIN_CLOCK_MARGIN,
    calibrate_time_offset,
)
from sonarslam.slam.run.sources import pose_source_by_name
from tests.echoes import shuffled_echoes

#: Tolerance (s) on the offset found. Measured on 300 s of the harbour, seeds 1-3, the sonar's
#: clock shifted by 0, 1 and 2 s: errors -0.034 to +0.101 s (the largest on seed 2 unshifted),
#: with 60 s windows (120 s windows: up to 0.28 s on seed 2, whose DVL has 47 s of gaps).
OFFSET_TOL_S = 0.15


@pytest.fixture(scope="module")
def harbour(simulated: Callable[..., Path]) -> Dataset:
    """300 s of the harbour world (raw intensities with background noise, sonar clock offset 0)."""
    return open_dataset(simulated("harbour", 2, 300.0))


@pytest.mark.parametrize("late_s", [0.0, 1.0])
def test_clock_offset_of_the_harbour_is_the_truth(harbour: Dataset, late_s: float) -> None:
    """The sonar's log times ``late_s`` late: the offset that puts them back is ``-late_s``."""
    assert harbour.config.sonar_time_offset_s == 0.0
    ds = replace(harbour, beams=harbour.beams.shifted(late_s))
    search = calibrate_time_offset(ds, pose_source_by_name(ds, "dr"))
    assert abs(search.best_offset_s + late_s) < OFFSET_TOL_S, search.best_offset_s
    assert search.decisive, search.verdict()
    # seeds 1-3, shifts 0-2 s: depth 3.9-6.4, margin 3.1-4.5; shuffled echoes <= 1.3 and <= 0.8
    assert search.depth > 1.4 * MIN_CLOCK_DEPTH
    assert search.margin > 1.4 * MIN_CLOCK_MARGIN
    assert search.offset_grid_s[0] == pytest.approx(-3.0)
    assert search.offset_grid_s[-1] == pytest.approx(3.0)


def test_clock_offset_without_geometry_is_not_decisive(harbour: Dataset) -> None:
    """Echoes shuffled among the beams: the objective is flat and says so."""
    ds = shuffled_echoes(harbour, seed=7)
    search = calibrate_time_offset(ds, pose_source_by_name(ds, "dr"))
    assert not search.decisive, search.verdict()
    assert search.depth < MIN_CLOCK_DEPTH or search.margin < MIN_CLOCK_MARGIN


def test_calibrate_cli_time_offset_or_refusal(
    harbour: Dataset,
    tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture[str],
) -> None:
    """A wrong configured offset (1 s) is found and replaced by the truth's (0) in the written
    sonarslam.toml, which a run reads back; a flat objective is refused (exit 1, one line,
    nothing written)."""
    wrong = tmp_path / "wrong.toml"
    wrong.write_text("[sonar]\ntime_offset_s = 1.0\n", encoding="utf-8")
    out = tmp_path / "sonarslam.toml"
    argv = ["calibrate", str(harbour.root), "--time-offset", "--config", str(wrong)]
    assert main([*argv, "--write", str(out)]) == 0
    line = [s for s in capsys.readouterr().out.splitlines() if "sonar clock offset" in s][0]
    found = float(line.split("poses: ")[1].split(" s")[0])
    assert abs(found) < OFFSET_TOL_S, line
    assert "configured: +1.000 s" in line
    written = tomllib.loads(out.read_text(encoding="utf-8"))["sonar"]["time_offset_s"]
    assert written == pytest.approx(found, abs=1e-3)
    assert open_dataset(harbour.root, config_override=out).config.sonar_time_offset_s == written

    flat = shuffled_echoes(harbour, seed=7)
    monkeypatch.setattr(calibrate_cli, "open_dataset", lambda *a, **k: flat)
    refused = tmp_path / "refused.toml"
    assert main(["calibrate", str(harbour.root), "--time-offset", "--write", str(refused)]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "too flat to give a sonar clock offset" in err[0], err
    assert "nothing written" in err[0]
    assert not refused.exists()


def test_an_offset_beyond_the_search_is_said_to_lie_beyond_it(
    harbour: Dataset, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    """The sonar's log 5 s late, beyond the +-3 s search: the least entropy sits at the
    search's edge, which is no minimum (it was called too flat, with advice to take a longer
    run); the refusal names the edge and how to search beyond it, and nothing is written."""
    late = replace(harbour, beams=harbour.beams.shifted(5.0))
    search = calibrate_time_offset(late, pose_source_by_name(late, "dr"))
    assert search.at_edge and not search.decisive, search.verdict()
    assert search.best_offset_s == pytest.approx(-3.0, abs=0.3)
    monkeypatch.setattr(calibrate_cli, "open_dataset", lambda *a, **k: late)
    assert main(["calibrate", str(harbour.root), "--time-offset"]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "edge of the search" in err[0] and "may lie beyond" in err[0], err


def test_calibrate_cli_time_offset_is_one_mode(harbour: Dataset) -> None:
    """--time-offset with another calibration is a setting error (exit 2)."""
    assert main(["calibrate", str(harbour.root), "--time-offset", "--ahrs"]) == 2


def test_map_entropy_variance_is_the_sampling_variance() -> None:
    """The delta-method variance of the plug-in entropy against the spread of the entropies of
    400 seeded draws of 3,000 points from fixed cell probabilities."""
    rng = np.random.default_rng(3)
    p = rng.dirichlet(np.full(60, 0.5))
    centres = np.column_stack([np.arange(60) + 0.5, np.zeros(60) + 0.5])
    draws = []
    predicted = []
    for _ in range(400):
        pts = centres[rng.choice(60, size=3000, p=p)]
        draws.append(map_entropy(pts, 1.0))
        predicted.append(map_entropy_variance(pts, 1.0))
    # the sample variance of 400 draws is within +-14 % (2 sigma of chi2(399)/399) of the truth
    assert np.var(draws, ddof=1) == pytest.approx(np.mean(predicted), rel=0.2)
    assert map_entropy_variance(np.zeros((0, 2)), 1.0) == 0.0
    assert map_entropy_variance(np.zeros((5, 2)), 1.0) == 0.0  # one cell: no spread
