"""``sonarslam info``: what a dataset holds, its settings and their sources."""

from __future__ import annotations

import argparse
import math
from pathlib import Path

from sonarslam.datasets.gates import DVL_MIN_SPEED_MPS, MAX_BEAMS_OUTSIDE_NAV
from sonarslam.datasets.navlog import describe_nav_log, is_nav_log, navlog_settings, read_nav_log
from sonarslam.datasets.ping360 import STILL_HEAD, is_ping360_log
from sonarslam.datasets.rosbag import bag_topics, is_bag
from sonarslam.datasets.source import Dataset, check_toml_inputs, open_dataset, resolve_source
from sonarslam.slam.model.motion import gyro_bias_against_heading
from sonarslam.slam.run.presets import parse_settings
from sonarslam.slam.run.settings import Setting, check_run_settings, dataset_settings, run_settings
from sonarslam.slam.run.sources import (
    CLOSED_LOOP_START_ONLY,
    DR_IGNORES,
    DVL_LEVER_ARM_TOLERANCE_M,
    DVL_SIGMA_OVER_SCATTER_MAX,
    dvl_lever_arm_from_turns,
    dvl_quality,
    start_pose,
    start_pose_origin,
    warn_dvl_lever_arm,
    warn_dvl_sigma,
)


def command(args: argparse.Namespace) -> int:
    settings = parse_settings(args.set)
    check_run_settings(settings)
    if Path(args.source).is_file() and is_nav_log(args.source):
        return _nav_log(args)
    if is_bag(args.source):
        check_toml_inputs(resolve_source(args.source), args.topics)
        topics = bag_topics(args.source, args.topics)
        print(f"{args.source}: {len(topics)} topics (role: what sonarslam reads it as)")
        width = max((len(t.topic) for t in topics), default=5)
        for t in topics:
            role = t.role or "-"
            print(
                f"  {t.topic:<{width}}  {t.msgtype:<46} {t.count:>8} msgs {t.rate_hz:>8.2f} Hz  {role}"
            )
    d = open_dataset(
        args.source,
        config_override=args.config,
        topics_file=args.topics,
        nav=args.nav,
        span_s=args.span,
    )
    t0, t1 = d.nav_span_s
    kind = (
        "ROS bag"
        if is_bag(d.root)
        else "Ping Viewer log"
        if is_ping360_log(d.root)
        else "logs in the marina layout"
    )
    print(f"{d.name}: {kind} at {d.root.resolve()}; calibration: {d.calibration}")
    if is_ping360_log(d.root):
        c = d.report.counts
        dropped = {
            k.removeprefix("ping360_"): v
            for k, v in c.items()
            if k.startswith("ping360_") and k != "ping360_gain_changes" and v
        }
        gain = c.get("ping360_gain_changes", 0)
        print(
            f"  Ping Viewer log: {len(d.beams)} beams of up to {d.config.sonar.n_bins} samples,"
            f" the head's bins {d.config.sonar.bin_size_m:.6g} m (sample period and [ping360]"
            f" speed_of_sound_mps), step {d.config.sonar.step_rad * 200 / math.pi:g} gradians;"
            f" other messages and bytes dropped: {dropped or 'none'}; gain_setting "
            + (f"changed {gain} time(s) (the intensities with it)" if gain else "constant")
        )
    _print_segments(d)
    if d.still:
        sonar = d.report.gaps.get("sonar")
        print(
            f"  sonar beams {len(d.beams)} over {d.beams.t_s[-1] - d.beams.t_s[0]:.1f} s"
            + (f"; gaps {sonar.count} (longest {sonar.longest_s:.1f} s)" if sonar else "")
        )
        print(f"  {STILL_HEAD}")
        print(f"  start pose: {start_pose_origin(d)}")
        _print_settings("dataset settings (sonarslam.toml keys)", dataset_settings(d, args.config))
        return 0
    nav = d.nav_beams()
    processed = ""
    if d.gps is not None and nav:
        t_start = start_pose(d)[0]
        n_run = sum(1 for b in nav if b.t >= t_start)
        processed = f"; a run processes the {n_run} from its start pose, the first GPS fix"
    outside = (
        f" (more than {MAX_BEAMS_OUTSIDE_NAV:.0%} outside: not used)"
        if len(d.beams) - len(nav) > MAX_BEAMS_OUTSIDE_NAV * len(d.beams)
        else ""
    )
    print(
        f"  sonar beams {len(d.beams)} ({len(nav)} inside the navigation span{processed})" + outside
    )
    print(f"  DVL rows {d.dvl.t.size} ({int((~d.dvl.valid).sum())} without bottom lock)")
    print(f"  AHRS rows {d.attitude.t.size}; GPS fixes {0 if d.gps is None else d.gps.t.size}")
    faults = {k: v for k, v in d.report.counts.items() if v}
    gaps = ", ".join(
        f"{name} {g.count} (longest {g.longest_s:.1f} s)" for name, g in d.report.gaps.items()
    )
    print(f"  gates (datasets/gates.py): {faults or 'nothing dropped'}; gaps: {gaps or 'none'}")
    print(f"  navigation span {t1 - t0:.1f} s")
    bias, se = gyro_bias_against_heading(d.attitude)
    print(
        f"  gyro against the AHRS heading's change: {math.degrees(bias):+.3f} ±"
        f" {math.degrees(se):.3f} deg/s"
        f" ({'a gyro bias' if abs(bias) > 2.0 * se else 'no bias beyond twice its standard error'};"
        " [motion] yaw_rate_source ="
        f" {d.config.yaw_rate_source!r})"
    )
    span = d.sonar_span_s
    if span is not None:
        print(
            f"  sonar span {span[1] - span[0]:.1f} s (first to last beam inside the navigation;"
            f" the line landmarks act there): {span[0] - t0:.1f} s to {span[1] - t0:.1f} s"
        )
    n, dq = d.config.noise, dvl_quality(d)
    slow = (
        f" (under {DVL_MIN_SPEED_MPS:g} m/s: implausibly slow, the velocities' unit?)"
        if dq["dvl_speed_p90_mps"] < DVL_MIN_SPEED_MPS
        else ""
    )
    print(
        f"  DVL speed over its locked rows (m/s): median {dq['dvl_speed_p50_mps']:.3g},"
        f" p90 {dq['dvl_speed_p90_mps']:.3g}{slow}"
    )
    print(
        f"  DVL scatter over {n.dvl_scatter_window_s or 60.0:g} s (m/s): "
        + ", ".join(f"p{p} {dq[f'dvl_scatter_p{p}_mps']:.3f}" for p in (10, 50, 90, 99))
    )
    if n.dvl_scatter_window_s > 0:
        first = dq["dvl_excess_from_s"]
        print(
            f"  DVL sigma {n.dvl_sigma_mps} m/s, plus the scatter's excess over"
            f" {n.dvl_nominal_scatter_mps} m/s: {dq['dvl_excess_s']:.0f} s of the run"
            + (f", first at {first:.0f} s" if first >= 0 else "")
        )
    else:
        print(f"  DVL sigma {n.dvl_sigma_mps} m/s (the scatter's excess is not added)")
    if warn_dvl_sigma(d, dq):
        print(
            f"  DVL sigma over its scatter's median: x{n.dvl_sigma_mps / dq['dvl_scatter_p50_mps']:.0f}"
            f" (over {DVL_SIGMA_OVER_SCATTER_MAX:g}: [noise] dvl_sigma_mps too large?)"
        )
    lever = dvl_lever_arm_from_turns(d)
    print(
        f"  DVL position its turns imply (m): x {lever.x_m:+.2f} ± {lever.x_se_m:.2f},"
        f" y {lever.y_m:+.2f} ± {lever.y_se_m:.2f}"
        f" ([mounting.dvl] x_m {d.config.dvl_mounting.x_m:g}, y_m {d.config.dvl_mounting.y_m:g})"
    )
    if warn_dvl_lever_arm(d, lever):
        print(
            f"  DVL lever arm: more than {DVL_LEVER_ARM_TOLERANCE_M:g} m from [mounting.dvl]"
            " x_m, y_m (in metres? a lateral axis of the wrong sign?)"
        )
    _print_settings("dataset settings (sonarslam.toml keys)", dataset_settings(d, args.config))
    print(f"  dead reckoning (--backend dr) ignores: {', '.join(DR_IGNORES)}")
    print(
        f"  the closed loops (--backend ekf, isam2) take {', '.join(CLOSED_LOOP_START_ONLY)} for"
        f" the start pose's heading only: their AHRS model is [noise] ahrs_white_sigma_deg"
        f" {n.ahrs_white_sigma_deg:g} deg of white noise plus a bias of [noise]"
        f" ahrs_bias_sigma_deg {n.ahrs_bias_sigma_deg:g} deg"
    )
    _print_settings("run settings (sonarslam run --set NAME=VALUE)", run_settings(d, settings))
    return 0


def _nav_log(args: argparse.Namespace) -> int:
    """A navigation log alone: what it holds, what a run would take from it."""
    path = Path(args.source)
    beside = path.parent / "sonarslam.toml"
    settings = navlog_settings(beside if beside.is_file() else None, args.config)
    for line in describe_nav_log(read_nav_log(path, settings)):
        print(line)
    return 0


def _print_segments(d: Dataset) -> None:
    """The log's segments (one range, gain, sector each), times as --span takes them."""
    if len(d.segments) < 2:
        return
    t0 = d.nav_span_s[0]
    origin = "the first beam (no navigation)" if d.still else "the start of the navigation"
    print(
        f"  {len(d.segments)} segments (a range, gain or sector each; each beam with its own bin"
        f" size; --span T0,T1 takes part of the log, s from {origin}):"
    )
    for k, g in enumerate(d.segments, 1):
        print(
            f"    {k}: {g.t0_s - t0:.3f} to {g.t1_s - t0:.3f} s, {g.beams} beams of"
            f" {g.n_bins} samples of {g.bin_size_m * 1000:.4g} mm (range {g.range_m:.2f} m),"
            f" {g.setting}"
        )


def _print_settings(title: str, settings: list[Setting]) -> None:
    print(f"{title}:")
    width = max(len(s.name) for s in settings)
    for s in settings:
        value = f"{s.value} {s.unit}" if s.unit and s.value is not None else f"{s.value}"
        print(f"  {s.name:<{width}}  {value:<24}  {s.source}")
