"""``sonarslam report``: run directories side by side."""

from __future__ import annotations

import argparse

from sonarslam.slam.io.files import check_output_dir
from sonarslam.slam.run.report import report
from sonarslam.slam.run.run import loop_line


def command(args: argparse.Namespace) -> int:
    check_output_dir(args.out)
    result = report(
        args.dirs,
        args.out,
        rpe_delta_m=args.rpe_delta,
        align=args.align,
        open_sources=not args.no_source,
    )
    for row in result.rows:
        if "loops" in row and row.get("ate_mean_m") is None:  # a run without GPS
            print(f"{row['method']} [{row['run']}, {row['dataset']}]: no GPS; {loop_line(row)}")
            continue
        if row.get("ate_n") is None:
            continue  # a published row
        sonar = (
            f"sonar span ATE mean {row['ate_sonar_mean_m']:.2f} m, max {row['ate_sonar_max_m']:.2f}; "
            if row.get("ate_sonar_mean_m") is not None
            else ""
        )
        truth = (
            f"; against the truth mean {row['ate_truth_mean_m']:.2f} m"
            if row.get("ate_truth_mean_m") is not None
            else ""
        )
        nees = row.get("nees_mean")
        print(
            f"{row['method']} [{row['run']}, {row['dataset']}]: {sonar}whole run ATE mean "
            f"{row['ate_mean_m']:.2f} m, max {row['ate_max_m']:.2f}{truth}; evo APE rmse "
            f"{row['evo_ape_rmse_m']:.2f} m"
            + (f"; pose NEES mean {nees:.2f}" if nees is not None else "")
        )
    print(f"report: {result.path.resolve()} ({len(result.figures)} figures)")
    return 0
