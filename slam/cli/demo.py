"""``sonarslam demo``: the main job of ``make run``."""

from __future__ import annotations

import argparse
from pathlib import Path

from slam.cli.common import EPILOG, Subparsers, add_quiet
from slam.io.files import check_output_dir
from slam.run.demo import main_job
from slam.run.run import results_table, summary_line


def add_parser(sub: Subparsers) -> None:
    p = sub.add_parser(
        "demo",
        help="the main job (make run): both closed loops and dead reckoning on the marina or a simulated harbour",
        epilog=EPILOG,
    )
    p.add_argument("--out", default="out", help="output directory (default out)")
    add_quiet(p)
    p.set_defaults(func=command)


def command(args: argparse.Namespace) -> int:
    check_output_dir(args.out)
    results = main_job(args.out, progress=not args.quiet)
    print("\nResults (ATE against GPS, no alignment):")
    for r in results:
        print("  " + summary_line(r.metrics))
    print("\nEvery trajectory, as published (no alignment) and after a rigid SE(2) fit:\n")
    print(results_table(results))
    print("\nOutputs and pictures:")
    print(f"  {Path(args.out).resolve()}  (*_scans_gps.png: the sonar map with GPS poses)")
    for r in results:
        if r.out_dir is not None:
            pics = ", ".join(p.name for p in sorted(r.out_dir.glob("*.png")))
            print(f"  {r.out_dir.resolve()}  ({pics})")
    return 0
