"""The silent miscalibrations of issue 41, each on a simulated harbour (seed 3, 300 s, with GPS;
its DVL 0.35 m forward of the body origin, as a BlueROV2's A50): first the wrong answer it gave
without a word (the simulator's truth the ruler), then the GPS-free check that now names the
setting. The false alarms of each check on correct runs are measured by
``benchmarks/miscalibration_checks.py`` (docs/bad-input.md gives the figures)."""

from __future__ import annotations

import math
import warnings
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from sonarslam.datasets.errors import DataWarning
from sonarslam.datasets.source import Dataset, open_dataset
from sonarslam.features.geometry import between
from sonarslam.slam.eval.ate import ate_against_truth
from sonarslam.slam.eval.loops import odometry_pairs
from sonarslam.slam.eval.truth import truth_trajectory
from sonarslam.slam.run.run import _warn_odometry, dataset_odometry_check, run
from sonarslam.slam.run.sources import (
    dead_reckoning_trajectory,
    dvl_lever_arm_from_turns,
    warn_dvl_lever_arm,
)

LEVER_M = 0.35


@pytest.fixture(scope="module")
def harbour(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The harbour's folder, its DVL at (0.35, 0) m and its sonarslam.toml saying so."""
    from sonarslam.datasets.simulator import make_scenario, simulate_records
    from sonarslam.datasets.simulator.writer import write_dataset

    sc = make_scenario("harbour", 3, 300.0)
    mount = replace(sc.dvl_mounting, x_m=LEVER_M, source="simulator truth")
    out = tmp_path_factory.mktemp("miscal")
    return write_dataset(simulate_records(replace(sc, dvl_mounting=mount)), out)


def _open(root: Path) -> Dataset:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DataWarning)  # the simulated DVL's gaps
        return open_dataset(root)


def _with_dvl_mounting(ds: Dataset, **changes: float) -> Dataset:
    return replace(
        ds, config=replace(ds.config, dvl_mounting=replace(ds.config.dvl_mounting, **changes))
    )


def _mirrored(ds: Dataset) -> Dataset:
    """The DVL's lateral axis of the wrong sign: its velocity mirrored across the body's x axis
    (the harbour's DVL is turned -90 deg, so this is its own x)."""
    assert ds.config.dvl_mounting.yaw_rad == pytest.approx(-math.pi / 2, abs=1e-12)
    v = ds.dvl.v_mps * np.array([-1.0, 1.0])
    return replace(ds, dvl=replace(ds.dvl, v_mps=v))


def _dr_ate(ds: Dataset) -> float:
    return ate_against_truth(dead_reckoning_trajectory(ds), truth_trajectory(ds)).ate_mean_m


def test_a_lever_arm_in_centimetres_is_named(harbour: Path) -> None:
    """``[mounting.dvl] x_m = 3.5`` for the true 0.35 m (under the 10 m bound, so read): dead
    reckoning's error against the truth 0.77 -> 4.08 m (rigidly aligned 0.10 -> 2.91 m),
    silently; the turns put the DVL at x = 0.49 ± 0.03 m (the simulated crab's correlation with
    the yaw rate adds ~0.1 m), and the warning names the key, the value and the unit."""
    ds = _open(harbour)
    wrong = _with_dvl_mounting(ds, x_m=10.0 * LEVER_M)
    right_ate, wrong_ate = _dr_ate(ds), _dr_ate(wrong)
    assert wrong_ate > right_ate + 2.5, (right_ate, wrong_ate)
    fit = dvl_lever_arm_from_turns(ds)
    assert fit.x_m == pytest.approx(LEVER_M, abs=0.25) and fit.x_se_m < 0.1
    assert fit.y_m == pytest.approx(0.0, abs=0.25) and fit.y_se_m < 0.1
    with pytest.warns(DataWarning) as record:
        message = warn_dvl_lever_arm(wrong)
    assert [str(w.message) for w in record] == [message]
    assert "[mounting.dvl] x_m = 3.5" in message and "centimetres or decimetres" in message
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert warn_dvl_lever_arm(ds) == ""


def test_a_mirrored_dvl_lateral_axis_is_named(harbour: Path) -> None:
    """The DVL's lateral velocity of the wrong sign (the vehicle's crab of +-4 deg turned the
    other way): dead reckoning's error against the truth 0.77 -> 1.75 m (rigidly aligned 0.10
    -> 0.86 m) with every check silent (the lever arm check cannot see a 0.35 m arm's mirror:
    0.7 m apart). The sonar's registrations fit the lateral velocity's gain at -0.49 ± 0.24
    (correct: +0.99 ± 0.10), and the run's odometry warning names the DVL's y."""
    ds = _open(harbour)
    bad = _mirrored(ds)
    assert _dr_ate(bad) > _dr_ate(ds) + 0.7
    right, wrong = dataset_odometry_check(ds), dataset_odometry_check(bad)
    assert right.lateral_gain == pytest.approx(1.0, abs=0.3) and not right.mirrored
    assert wrong.mirrored and wrong.lateral_gain < 0.0
    assert not wrong.turned  # the direction of travel hardly changes
    with pytest.warns(DataWarning, match=r"lateral axis has the wrong sign.*negate the DVL's y"):
        _warn_odometry(bad, wrong)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        _warn_odometry(ds, right)


def test_a_range_scale_four_percent_off_is_named_on_a_run_with_gps(
    harbour: Path, tmp_path: Path
) -> None:
    """``[sonar] bin_size_m`` 4 % long (a speed of sound 4 % off): the sonar's registrations are
    x1.04 the truth's motion between their scans, and a run with GPS, whose odometry check did
    not run, said nothing; now ``run --backend dr`` names the setting."""
    ds = _open(harbour)
    toml = tmp_path / "range.toml"
    toml.write_text(f"[sonar]\nbin_size_m = {1.04 * ds.config.sonar.bin_size_m}\n")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DataWarning)
        long = open_dataset(harbour, config_override=toml)
    truth = truth_trajectory(long)
    ratios = []
    for p in odometry_pairs(long, dead_reckoning_trajectory(long), 5.0):
        if p.sonar is not None:
            t = np.asarray(truth.poses(np.array([p.t0_s, p.t1_s])))
            ratios.append(math.hypot(*p.sonar[:2]) / math.hypot(*between(t[0], t[1])[:2]))
    assert len(ratios) >= 5 and float(np.median(ratios)) == pytest.approx(1.04, abs=0.01)
    with warnings.catch_warnings(record=True) as record:
        warnings.simplefilter("always")
        run(harbour, "dr", tmp_path / "run", progress=False, config=toml)
    said = [str(w.message) for w in record if "the sonar's lengths are x1.0" in str(w.message)]
    assert len(said) == 1 and "[sonar] bin_size_m" in said[0], [str(w.message) for w in record]


def test_a_sonar_clock_half_a_second_late_is_named(harbour: Path, tmp_path: Path) -> None:
    """``[sonar] time_offset_s = 0.5`` for the true 0 (the sonar's clock half a second later
    than the setting says): the EKF's error against the truth 0.74 -> 0.84 m (rigidly aligned
    0.07 -> 0.15 m; 1 s: 1.08 and 0.43 m), silently. The run's clock check (the map-entropy
    search of ``calibrate --time-offset`` over +-1.5 s with dead reckoning's poses) finds the
    sharpest map at +0.07 s and names the setting; the correct clock stays silent."""
    from sonarslam.slam.run.calibration import ekf_closed_loop, sonar_clock_doubt

    toml = tmp_path / "clock.toml"
    toml.write_text("[sonar]\ntime_offset_s = 0.5\n")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DataWarning)
        late = open_dataset(harbour, config_override=toml)
    ates = []
    for ds in (_open(harbour), late):
        res = ekf_closed_loop(ds)
        truth = truth_trajectory(ds)
        ates.append(ate_against_truth(res.trajectory, truth, align=True).ate_mean_m)
    assert ates[1] > ates[0] + 0.05, ates
    with warnings.catch_warnings(record=True) as record:
        warnings.simplefilter("always")
        run(harbour, "dr", tmp_path / "late", progress=False, config=toml)
    said = [str(w.message) for w in record if "time_offset_s" in str(w.message)]
    assert len(said) == 1, said
    assert "not the configured 0.5 s" in said[0] and "calibrate SOURCE --time-offset" in said[0]
    right = _open(harbour)
    assert sonar_clock_doubt(right, dead_reckoning_trajectory(right)) is None
