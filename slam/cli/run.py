"""``sonarslam run``: one back end on a dataset, evaluated against GPS."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from sonarslam.slam.run.presets import parse_settings
from sonarslam.slam.run.run import loop_line, run, smoothed_lines, summary_line


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
        loops_rel_s=args.loop,
        nav=args.nav,
        span_s=args.span,
    )
    m = result.metrics
    print(f"calibration: {m['calibration']}")
    print(f"start pose: {m['start_pose']}; evaluation: {m['evaluation']}")
    if "extractor_preset" in m:
        print(f"extractor preset: {m['extractor_preset']} (slam/run/presets.py)")
    print(summary_line(m))
    for line in smoothed_lines(m):
        print(line)
    if "loops" in m:
        print(loop_line(m))
    if "health_line" in m:
        print(m["health_line"])
    out = result.out_dir.resolve() if result.out_dir else Path(args.out)
    print(f"outputs: {out} ({', '.join(sorted(p.name for p in result.files))})")
    for note in result.notes:
        print(f"note: {note}")
    if args.strict and m.get("health_ok") is False:
        print(
            f"sonarslam run: error: --strict: {m['health_issues']} health issue(s), first:"
            f" {m['health_first_issue']}",
            file=sys.stderr,
        )
        return 1
    return 0
