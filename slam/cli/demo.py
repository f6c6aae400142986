"""``sonarslam demo``: the main job of ``make run``."""

from __future__ import annotations

import argparse
from pathlib import Path

from sonarslam.slam.cli.common import EPILOG, Subparsers, add_quiet
from sonarslam.slam.io.files import check_output_dir
from sonarslam.slam.run.demo import SIM_DURATION_S, demo_source, main_job
from sonarslam.slam.run.run import results_table, summary_line


def add_parser(sub: Subparsers) -> None:
    p = sub.add_parser(
        "demo",
        help="the main job (make run): both closed loops and dead reckoning on the marina or, "
        "without it, a simulated harbour",
        epilog=EPILOG,
    )
    p.add_argument("--out", default="out", help="output directory (default out)")
    p.add_argument(
        "--sim-duration",
        type=float,
        default=SIM_DURATION_S,
        help=f"length of the simulated harbour when there is no marina (s, default {SIM_DURATION_S:g})",
    )
    add_quiet(p)
    p.set_defaults(func=command)


def command(args: argparse.Namespace) -> int:
    check_output_dir(args.out)
    source = demo_source(args.sim_duration)
    print(f"Running {source.description}.", flush=True)
    results = main_job(
        args.out, progress=not args.quiet, source=source, duration_s=args.sim_duration
    )
    if source.simulated:
        print(
            "\nResults (ATE against the simulator's truth, no alignment, then rigidly aligned;"
            " against its simulated GPS after):"
        )
    else:
        print("\nResults (ATE against GPS, no alignment):")
    for r in results:
        print("  " + summary_line(r.metrics))
    print("\nEvery trajectory, as published (no alignment) and after a rigid SE(2) fit:\n")
    print(results_table(results))
    print("\nOutputs and pictures:")
    what = "the simulated GPS" if source.simulated else "GPS"
    print(f"  {Path(args.out).resolve()}  (*_scans_gps.png: the sonar map with {what} poses)")
    for r in results:
        if r.out_dir is not None:
            pics = ", ".join(p.name for p in sorted(r.out_dir.glob("*.png")))
            print(f"  {r.out_dir.resolve()}  ({pics})")
    return 0
