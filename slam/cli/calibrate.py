"""``sonarslam calibrate``: GPS-free calibrations (sonar yaw, the sonar clock offset, AHRS yaw,
AHRS deviation, the sonar's range offset, a line's systematic error)."""

from __future__ import annotations

import argparse
import math
import warnings
from dataclasses import replace
from pathlib import Path

from sonarslam.datasets.config import DatasetConfig, dump_dataset_config
from sonarslam.datasets.errors import DataError, DataWarning
from sonarslam.datasets.ping360 import is_ping360_log, ping360_table
from sonarslam.datasets.source import Dataset, open_dataset
from sonarslam.settings import SettingError
from sonarslam.slam.run.calibration import (
    calibrate_ahrs_deviation,
    calibrate_ahrs_yaw,
    calibrate_sonar_yaw,
    calibrate_time_offset,
    ekf_closed_loop,
    yaw_change_doubt,
)
from sonarslam.slam.run.closed_loop import ClosedLoopResult
from sonarslam.slam.run.sonar_calibration import calibrate_line_noise, calibrate_range_offset
from sonarslam.slam.run.sources import pose_source_by_name


def _open(args: argparse.Namespace) -> Dataset:
    dataset = open_dataset(args.source, config_override=args.config, nav=args.nav, span_s=args.span)
    if args.start is not None:
        dataset = replace(dataset, start_enu=args.start)
    print(f"calibration of {dataset.name}: {dataset.calibration}")
    return dataset


def _write(args: argparse.Namespace, config: DatasetConfig) -> None:
    """--write: the whole calibration, with what was found, to a sonarslam.toml (a .bin's
    [ping360] table kept)."""
    if args.write:
        path = Path(args.write)
        text = dump_dataset_config(config)
        if is_ping360_log(args.source):
            text += ping360_table(args.source, path, args.nav or None)
        path.write_text(text, encoding="utf-8")
        print(f"written: {path}")


def _ahrs_deviation(args: argparse.Namespace) -> int:
    dataset = _open(args)
    b0, c0 = (math.degrees(v) for v in dataset.config.ahrs_deviation_rad)
    print(
        f"AHRS deviation from the EKF's line re-observations (GPS-free), from [{b0:.2f}, {c0:.2f}] deg:"
    )

    label = ["ekf"]

    def progress(k: int, n: int) -> None:
        label[0] = f"calibrate ahrs-deviation {k}/{n} (ekf)"

    def closed_loop(ds: Dataset) -> ClosedLoopResult:
        return ekf_closed_loop(ds, None if args.quiet else label[0])

    steps = calibrate_ahrs_deviation(
        dataset, closed_loop, iterations=args.iterations, progress=progress
    )
    for k, (dev, n) in enumerate(steps, start=1):
        print(
            f"  iteration {k}: [{math.degrees(dev[0]):.2f}, {math.degrees(dev[1]):.2f}] deg ({n} lines)"
        )
    b, c = (math.degrees(v) for v in steps[-1][0])
    print(f"put it under [motion] as ahrs_deviation_deg = [{b:.2f}, {c:.2f}]")
    b_rad, c_rad = (float(v) for v in steps[-1][0])
    _write(args, replace(dataset.config, ahrs_deviation_rad=(b_rad, c_rad)))
    return 0


def _time_offset(args: argparse.Namespace) -> int:
    """--time-offset: the sonar clock offset of least map entropy, or a refusal when the
    objective is flat."""
    dataset = _open(args)
    window = 60.0 if args.window is None else args.window
    result = calibrate_time_offset(dataset, pose_source_by_name(dataset, args.poses), window)
    if result.at_edge:
        lo, hi = result.offset_grid_s[0], result.offset_grid_s[-1]
        raise DataError(
            dataset.root,
            None,
            f"the least map entropy lies at the edge of the search ({result.best_offset_s:+.3f} s;"
            f" searched {lo:+.2f} to {hi:+.2f} s around the configured"
            f" {result.configured_offset_s:+.3f} s): the sonar clock offset may lie beyond it;"
            " set [sonar] time_offset_s to that edge in a --config file and search again (the"
            " search is centred on the configured offset); nothing written",
        )
    if not result.decisive:
        raise DataError(
            dataset.root,
            None,
            f"the map-sharpness objective is too flat to give a sonar clock offset (least entropy"
            f" at {result.best_offset_s:+.3f} s, {result.verdict()}): the echoes do not show the"
            " same walls while the vehicle turns; calibrate on a longer run, or try another"
            f" --window (now {window:g} s); nothing written",
        )
    print(
        f"sonar clock offset with {args.poses} poses: {result.best_offset_s:+.3f} s (configured:"
        f" {result.configured_offset_s:+.3f} s; searched {result.offset_grid_s[0]:+.2f} to"
        f" {result.offset_grid_s[-1]:+.2f} s; {result.verdict()}); put it under [sonar]"
        " time_offset_s in sonarslam.toml"
    )
    _write(args, replace(dataset.config, sonar_time_offset_s=round(result.best_offset_s, 3)))
    return 0


def _sonar(args: argparse.Namespace) -> int:
    """--range-offset and/or --line-noise; with both, the lines see the offset just found."""
    dataset = _open(args)
    if args.range_offset:
        fit = calibrate_range_offset(dataset)
        print(
            f"range offset of the kept echoes (GPS-free, {fit.method}): {fit.offset_m:.3f} m "
            f"(IQR {fit.iqr_m:.3f} m, {fit.n} echoes; configured "
            f"{dataset.config.sonar.range_offset_m:.3f} m); put it under [sonar] range_offset_m"
        )
        sonar = replace(dataset.config.sonar, range_offset_m=fit.offset_m)
        dataset = replace(dataset, config=replace(dataset.config, sonar=sonar))
    if args.line_noise:
        dataset = replace(dataset, config=_line_noise(dataset))
    _write(args, dataset.config)
    return 0


def _line_noise(dataset: Dataset) -> DatasetConfig:
    fit = calibrate_line_noise(dataset)
    n = dataset.config.noise
    print(
        f"a line's systematic error (GPS-free, with range offset "
        f"{dataset.config.sonar.range_offset_m:.3f} m; {fit.n_pairs} pairs of {fit.n_lines} lines): "
        f"sigma rho {fit.sigma_rho_m:.3f} m, sigma theta {math.degrees(fit.sigma_theta_rad):.2f}"
        f" deg (configured {n.line_sigma_rho_m:.3f} m, {n.line_sigma_theta_deg:.2f} deg); pair "
        f"NEES median {fit.nees_median_before:.2f} -> {fit.nees_median_after:.2f} (chi2(2): "
        f"1.39), {100 * fit.outside_99_after:.1f} % outside the 99 % gate; put them under "
        f"[noise] as line_sigma_rho_m and line_sigma_theta_deg"
    )
    noise = replace(
        n,
        line_sigma_rho_m=float(fit.sigma_rho_m),
        line_sigma_theta_deg=float(math.degrees(fit.sigma_theta_rad)),
    )
    return replace(dataset.config, noise=noise)


def command(args: argparse.Namespace) -> int:
    modes = [
        name
        for name, on in (
            ("--time-offset", args.time_offset),
            ("--ahrs", args.ahrs),
            ("--ahrs-deviation", args.ahrs_deviation),
            ("--range-offset/--line-noise", args.range_offset or args.line_noise),
        )
        if on
    ]
    if len(modes) > 1:
        raise SettingError(
            " and ".join(modes),
            "one calibration at a time (--range-offset and --line-noise may go together)",
        )
    if args.ahrs_deviation:
        return _ahrs_deviation(args)
    if args.time_offset:
        return _time_offset(args)
    if args.range_offset or args.line_noise:
        return _sonar(args)
    dataset = _open(args)
    if args.ahrs:
        fit = calibrate_ahrs_yaw(dataset)
        amp = math.degrees(math.hypot(*fit.harmonics_rad[:2]))
        print(
            f"AHRS mounting yaw from the DVL compass (GPS-free): "
            f"{math.degrees(fit.ahrs_yaw_rad):.2f} deg (configured: "
            f"{math.degrees(dataset.config.ahrs_mounting.yaw_rad):.2f} deg); DVL compass - AHRS "
            f"yaw = {math.degrees(fit.offset_rad):.2f} deg over headings (time mean "
            f"{math.degrees(fit.time_mean_rad):.2f} deg), deviation {amp:.1f} deg, residual sd "
            f"{math.degrees(fit.residual_sd_rad):.2f} deg; put it under [mounting.ahrs] yaw_deg"
        )
        change = ", ".join(
            f"{lag:g} s {math.degrees(v):.2f}" for lag, v in fit.residual_change_rad.items()
        )
        print(
            f"  the residual's RMS change over a lag (deg): {change} (a walking bias grows as"
            " sqrt(lag): [noise] ahrs_bias_walk_deg_per_sqrt_s)"
        )
        mount = replace(
            dataset.config.ahrs_mounting,
            yaw_rad=float(fit.ahrs_yaw_rad),
            source="sonarslam calibrate --ahrs (GPS-free)",
        )
        _write(args, replace(dataset.config, ahrs_mounting=mount))
        return 0
    poses = pose_source_by_name(dataset, args.poses)
    window = 120.0 if args.window is None else args.window
    result = calibrate_sonar_yaw(dataset, poses, window_s=window)
    current = math.degrees(dataset.config.sonar_mounting.yaw_rad)
    if not result.decisive:
        raise DataError(
            dataset.root,
            None,
            f"the map-sharpness objective is too flat to give a sonar yaw (least entropy at "
            f"{math.degrees(result.best_yaw_rad):.2f} deg, {result.verdict()}): the echoes do "
            "not show the same walls from several places, or the sonar is mirrored (a wrong "
            "[sonar] angle_sense: no yaw then brings its views of a wall together); calibrate on "
            "a longer run that passes walls more than once, try the other angle_sense, or try "
            f"another --window (now {window:g} s); nothing written",
        )
    found = (
        f"sonar mounting yaw with {args.poses} poses: {math.degrees(result.best_yaw_rad):.2f} deg "
        f"(configured: {current:.2f} deg; {result.verdict()})"
    )
    doubt = yaw_change_doubt(dataset, result.best_yaw_rad)
    if doubt is not None and not dataset.config.sonar_mounting.assumed:
        if not args.accept_large_yaw:
            raise DataError(
                dataset.root,
                None,
                f"{found}: {doubt}; check those mountings and calibrate again, or give"
                " --accept-large-yaw to take the sonar's; nothing written",
            )
    print(f"{found}; put it under [mounting.sonar] yaw_deg in sonarslam.toml")
    if doubt is not None:
        warnings.warn(f"{dataset.root}: {doubt}", DataWarning, stacklevel=2)
    mount = replace(
        dataset.config.sonar_mounting,
        yaw_rad=float(result.best_yaw_rad),
        source=f"map entropy over {args.poses} poses (sonarslam calibrate)",
    )
    _write(args, replace(dataset.config, sonar_mounting=mount))
    return 0
