"""GPS-free calibrations of the line model (slam.run.sonar_calibration), scored against the
simulator's true walls: the range offset of the kept echoes and a line's systematic error."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace

import numpy as np
import pytest

from sonarslam.datasets.source import Dataset
from sonarslam.features.extractor import LineExtractor
from sonarslam.slam.cli.main import main
from sonarslam.slam.eval.consistency import mean_nees_band
from sonarslam.slam.eval.lines import GATE_RAD, HARBOUR_GATE_M, match_features
from sonarslam.slam.eval.truth import truth_trajectory, truth_walls
from sonarslam.slam.run.presets import extractor_config
from sonarslam.slam.run.sonar_calibration import (
    RangeOffsetFit,
    calibrate_line_noise,
    calibrate_range_offset,
)


@pytest.fixture(scope="module")
def drift(opened: Callable[..., Dataset]) -> Dataset:
    """900 s of the drift world: its echoes rise on the wall's face and peak 0.25 m behind
    (the same run as tests/test_dvl_scale.py's, simulated and read once per session)."""
    return opened("drift", 2, 900.0)


@pytest.fixture(scope="module")
def offset_fit(drift: Dataset) -> RangeOffsetFit:
    """``calibrate_range_offset`` on the drift run, once for the module (it is deterministic)."""
    return calibrate_range_offset(drift)


#: _against_truth's results by (dataset, range offset, sigmas): the extraction is deterministic
#: and several tests score the same lines.
_SCORED: dict[tuple[str, float, tuple[float, float]], tuple[float, np.ndarray]] = {}


def _against_truth(
    ds: Dataset, sigmas: tuple[float, float] = (0.0, 0.0)
) -> tuple[float, np.ndarray]:
    """Lines extracted with the true poses: mean rho error (m, > 0 behind the wall), NEES."""
    key = (str(ds.root), ds.config.sonar.range_offset_m, sigmas)
    if key in _SCORED:
        return _SCORED[key]
    cfg = extractor_config("default").replace(
        line_sigma_rho_m=sigmas[0], line_sigma_theta_rad=sigmas[1]
    )
    extractor = LineExtractor(cfg, ds.config.sonar, ds.config.sonar_mounting, truth_trajectory(ds))
    lines = [f for b in ds.nav_beams() for f in extractor.add(b)]
    matched = [
        m for m in match_features(lines, truth_walls(ds), HARBOUR_GATE_M, GATE_RAD) if m.matched
    ]
    assert len(matched) > 100
    _SCORED[key] = (
        float(np.mean([m.error[0] for m in matched])),
        np.array([m.nees for m in matched]),
    )
    return _SCORED[key]


def _with_offset(ds: Dataset, offset_m: float) -> Dataset:
    sonar = replace(ds.config.sonar, range_offset_m=offset_m)
    return replace(ds, config=replace(ds.config, sonar=sonar))


def test_the_range_offset_puts_the_lines_on_the_walls(
    drift: Dataset, offset_fit: RangeOffsetFit
) -> None:
    bias_raw, _ = _against_truth(drift)
    assert bias_raw > 0.08  # the kept peaks lie behind the faces
    fit = offset_fit
    assert fit.method.startswith("raw echoes") and fit.n > 1000
    assert 0.05 < fit.offset_m < 0.25
    bias, _ = _against_truth(_with_offset(drift, fit.offset_m))
    assert abs(bias) < 0.04


def test_the_line_noise_makes_the_lines_no_longer_overconfident(
    drift: Dataset, offset_fit: RangeOffsetFit
) -> None:
    ds = _with_offset(drift, offset_fit.offset_m)
    _, nees0 = _against_truth(ds)
    _, hi = mean_nees_band(nees0.size, 2)
    assert nees0.mean() > hi  # the fit's covariance alone: the echoes' noise only
    fit = calibrate_line_noise(ds)
    assert fit.nees_median_after == pytest.approx(1.386, abs=0.01)
    assert fit.outside_99_after < 0.10  # the pairs' tails: heavier than chi2(2)'s 1 %
    _, nees = _against_truth(ds, (fit.sigma_rho_m, fit.sigma_theta_rad))
    assert nees.mean() < hi  # against the true walls: not overconfident ...
    assert 0.9 < np.median(nees) < 1.9  # ... nor padded: chi2(2)'s median is 1.386


def test_the_command_measures_the_lines_with_the_offset_it_just_found(
    drift: Dataset, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["calibrate", str(drift.root), "--range-offset", "--line-noise", "--quiet"]) == 0
    calibration_line, offset_line, noise_line = capsys.readouterr().out.strip().splitlines()
    assert calibration_line.startswith(f"calibration of {drift.name}: ")
    offset = float(offset_line.split("peak - half-rise): ")[1].split(" m")[0])
    assert 0.05 < offset < 0.25
    assert f"with range offset {offset:.3f} m" in noise_line


def test_thresholded_runs_have_no_offset(marina: Dataset) -> None:
    fit = calibrate_range_offset(marina, every=20)
    assert fit.offset_m == 0.0 and fit.n > 1000 and fit.method.startswith("thresholded")
