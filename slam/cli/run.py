"""``sonarslam run``: one back end on a dataset, evaluated against GPS."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from sonarslam.slam.cli.common import EPILOG, Subparsers, add_quiet, add_source, add_start
from sonarslam.slam.run.presets import parse_settings
from sonarslam.slam.run.run import backend_names, run, summary_line


def add_parser(sub: Subparsers) -> None:
    p = sub.add_parser(
        "run",
        help="run a back end and evaluate it against GPS (and the truth on simulated data)",
        epilog=EPILOG,
    )
    add_source(p)
    p.add_argument(
        "--backend",
        default="dr",
        choices=backend_names(),
        help="dr (dead reckoning), gps (GPS+AHRS), ekf, isam2 (default dr)",
    )
    p.add_argument("--out", required=True, help="output directory")
    add_start(p)
    p.add_argument(
        "--topics",
        metavar="TOML",
        help="a bag's roles: [topics] sonar, dvl, imu, gps = topic names (default: by message"
        " type, or [topics] of the bag's sonarslam.toml)",
    )
    add_quiet(p)
    p.add_argument(
        "--batch",
        action="store_true",
        help="isam2 only: a final batch Levenberg-Marquardt pass (isam2_batch.tum, ate_*_batch_m)",
    )
    p.add_argument(
        "--config",
        default=None,
        help="a sonarslam.toml-format file whose keys replace the dataset's calibration"
        " (e.g. [mounting.ahrs] yaw_deg); the one used is written to OUT/config_used.toml",
    )
    p.add_argument(
        "--set",
        action="append",
        default=[],
        metavar="SCOPE.FIELD=VALUE",
        help="an extractor or back-end setting, repeatable: extractor.max_range_m=25,"
        " ekf.extent_margin_m=10, isam2.robust=cauchy, isam2.association=nn (fields of"
        " ExtractorConfig, EkfConfig, GraphConfig); recorded in metrics.json",
    )
    p.add_argument(
        "--strict",
        action="store_true",
        help="exit 1 when the health monitor finds the closed loop inconsistent with its own"
        " model (metrics.json health_*; the outputs are written all the same)",
    )
    p.set_defaults(func=command)


def command(args: argparse.Namespace) -> int:
    result = run(
        args.source,
        args.backend,
        args.out,
        progress=not args.quiet,
        batch=args.batch,
        config=args.config,
        settings=parse_settings(args.set),
        start_enu=args.start,
        topics_file=args.topics,
    )
    m = result.metrics
    print(f"calibration: {m['calibration']}")
    print(f"start pose: {m['start_pose']}; evaluation: {m['evaluation']}")
    if "extractor_preset" in m:
        print(f"extractor preset: {m['extractor_preset']} (slam/run/presets.py)")
    print(summary_line(m))
    if "health_line" in m:
        print(m["health_line"])
    out = result.out_dir.resolve() if result.out_dir else Path(args.out)
    print(f"outputs: {out} ({', '.join(sorted(p.name for p in result.files))})")
    if args.strict and m.get("health_ok") is False:
        print(
            f"sonarslam run: error: --strict: {m['health_issues']} health issue(s), first:"
            f" {m['health_first_issue']}",
            file=sys.stderr,
        )
        return 1
    return 0
