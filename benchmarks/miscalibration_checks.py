"""The GPS-free checks of the silent miscalibrations (issue 41) on simulated runs: each check on
the correct run (a flag is a false alarm) and with its error injected (a flag is a find).

For each world and seed, a run of ``--duration`` s is simulated with its DVL ``LEVER_TRUE_M``
forward of the body origin (a BlueROV2's A50 sits about there) and opened with:

* ``correct``: the simulator's own calibration;
* ``lever_cm``: ``[mounting.dvl] x_m`` ten times too long (3.5 for 0.35 m): the lever-arm check
  (:func:`sonarslam.slam.run.sources.warn_dvl_lever_arm`);
* ``mirror``: the DVL's velocity mirrored across the body's forward axis (the lateral axis of
  the wrong sign): the odometry check's lateral gain (:attr:`OdometryCheck.mirrored`);
* ``range``: ``[sonar] bin_size_m`` 4 % long (a speed of sound 4 % off): the odometry check's
  length ratio (``run``'s softer warning, :func:`sonarslam.slam.run.run.odometry_scale_tolerance`);
* ``clock 0.5``, ``clock 1.0``: ``[sonar] time_offset_s`` 0.5 and 1 s above the truth (the
  sonar's clock that much later than the setting says): the run's clock check
  (:func:`sonarslam.slam.run.calibration.sonar_clock_doubt`).

The truth is not looked at: only whether each check speaks. ``--marina`` adds the marina's
correct run (``SONARSLAM_DATA``). Usage::

    .venv/bin/python benchmarks/miscalibration_checks.py --kinds harbour --seeds 1-20
"""

from __future__ import annotations

import argparse
import math
import sys
import tempfile
import warnings
from dataclasses import replace
from pathlib import Path

from sonarslam.datasets.source import Dataset, open_dataset
from sonarslam.slam.run.calibration import sonar_clock_doubt
from sonarslam.slam.run.run import dataset_odometry_check, odometry_scale_tolerance
from sonarslam.slam.run.sources import (
    DVL_LEVER_ARM_TOLERANCE_M,
    dead_reckoning_trajectory,
    dvl_lever_arm_from_turns,
)

LEVER_TRUE_M = 0.35
RANGE_SCALE = 1.04


def simulate(kind: str, seed: int, duration_s: float, out: Path) -> Dataset:
    """A simulated run with its DVL at ``LEVER_TRUE_M`` forward, opened."""
    from sonarslam.datasets.simulator import make_scenario, simulate_records
    from sonarslam.datasets.simulator.writer import write_dataset

    sc = make_scenario(kind, seed, duration_s)
    mount = replace(sc.dvl_mounting, x_m=LEVER_TRUE_M, source="simulator truth")
    return open_dataset(write_dataset(simulate_records(replace(sc, dvl_mounting=mount)), out))


def with_config(ds: Dataset, **changes: object) -> Dataset:
    return replace(ds, config=replace(ds.config, **changes))


def mirrored(ds: Dataset) -> Dataset:
    """The DVL's velocity mirrored across the body's forward axis."""
    a = ds.config.dvl_mounting.yaw_rad
    c2, s2 = math.cos(2.0 * a), math.sin(2.0 * a)
    v = ds.dvl.v_mps
    flipped = v.copy()
    flipped[:, 0] = c2 * v[:, 0] - s2 * v[:, 1]
    flipped[:, 1] = -s2 * v[:, 0] - c2 * v[:, 1]
    return replace(ds, dvl=replace(ds.dvl, v_mps=flipped))


def lever_flag(ds: Dataset) -> tuple[bool, str]:
    fit = dvl_lever_arm_from_turns(ds)
    m = ds.config.dvl_mounting
    off = math.hypot(fit.x_m - m.x_m, fit.y_m - m.y_m)
    return fit.decisive and off > DVL_LEVER_ARM_TOLERANCE_M, (
        f"x {fit.x_m:+.2f}±{fit.x_se_m:.2f} y {fit.y_m:+.2f}±{fit.y_se_m:.2f}"
    )


def range_flag(ds: Dataset, check) -> bool:
    s, se = check.scale, check.scale_se
    return (
        check.accepted >= 4
        and math.isfinite(s)
        and abs(s - 1.0) > odometry_scale_tolerance(ds)
        and abs(s - 1.0) > 3.0 * se
    )


def clock_flag(ds: Dataset) -> bool:
    return sonar_clock_doubt(ds, dead_reckoning_trajectory(ds)) is not None


def late_clock(ds: Dataset, late_s: float, tmp: Path) -> Dataset:
    """``ds`` reopened with ``[sonar] time_offset_s`` ``late_s`` above its own."""
    toml = tmp / f"clock{late_s}.toml"
    toml.write_text(f"[sonar]\ntime_offset_s = {ds.config.sonar_time_offset_s + late_s}\n")
    return open_dataset(ds.root, config_override=toml)


def measure(name: str, ds: Dataset, tmp: Path, inject: bool = True) -> list[str]:
    rows = [f"{name} correct: clock {clock_flag(ds)}"]
    odo = dataset_odometry_check(ds)
    lever, text = lever_flag(ds)
    rows.append(
        f"{name} correct: lever {lever} ({text}); mirror {odo.mirrored} (gain"
        f" {odo.lateral_gain:+.2f}±{odo.lateral_gain_se:.2f}); range {range_flag(ds, odo)}"
        f" (x{odo.scale:.3f}±{odo.scale_se:.3f}, {odo.accepted} reg.); turned {odo.turned}"
    )
    if not inject:
        return rows
    m = ds.config.dvl_mounting
    wrong = with_config(ds, dvl_mounting=replace(m, x_m=10.0 * m.x_m))
    lever, text = lever_flag(wrong)
    rows.append(f"{name} lever_cm: lever {lever} ({text})")
    odo = dataset_odometry_check(mirrored(ds))
    rows.append(
        f"{name} mirror: mirror {odo.mirrored} (gain {odo.lateral_gain:+.2f}±"
        f"{odo.lateral_gain_se:.2f}); lever {lever_flag(mirrored(ds))[0]}"
    )
    head = ds.config.sonar
    scaled = with_config(ds, sonar=replace(head, bin_size_m=head.bin_size_m * RANGE_SCALE))
    odo = dataset_odometry_check(scaled)
    rows.append(
        f"{name} range: range {range_flag(scaled, odo)} (x{odo.scale:.3f}±{odo.scale_se:.3f},"
        f" {odo.accepted} reg.)"
    )
    for late_s in (0.5, 1.0):
        doubt = sonar_clock_doubt(
            late := late_clock(ds, late_s, tmp), dead_reckoning_trajectory(late)
        )
        rows.append(f"{name} clock {late_s}: clock {doubt is not None} ({doubt})")
    return rows


def _seeds(text: str) -> list[int]:
    a, _, b = text.partition("-")
    return list(range(int(a), int(b or a) + 1))


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--kinds", default="harbour")
    parser.add_argument("--seeds", default="1-10")
    parser.add_argument("--duration", type=float, default=300.0)
    parser.add_argument("--marina", action="store_true")
    args = parser.parse_args(argv)
    warnings.simplefilter("ignore")
    with tempfile.TemporaryDirectory() as tmp:
        for kind in args.kinds.split(","):
            for seed in _seeds(args.seeds):
                ds = simulate(kind, seed, args.duration, Path(tmp) / f"{kind}{seed}")
                for row in measure(f"{kind} {seed}", ds, Path(tmp)):
                    print(row, flush=True)
        if args.marina:
            for row in measure("marina", open_dataset("marina"), Path(tmp), inject=True):
                print(row, flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
