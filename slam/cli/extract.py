"""``sonarslam extract``: the line features of a dataset with one pose source."""

from __future__ import annotations

import argparse
from dataclasses import replace
from pathlib import Path

from sonarslam.datasets.source import Dataset, open_dataset
from sonarslam.slam.cli.common import poses_for
from sonarslam.slam.io.files import check_output_dir
from sonarslam.slam.run.extraction import extract
from sonarslam.slam.run.sources import start_pose_origin


def command(args: argparse.Namespace) -> int:
    check_output_dir(args.out)  # before the data is read, as extract() does
    opened = open_dataset(args.source, nav=args.nav, span_s=args.span)
    source: Dataset = replace(opened, start_enu=args.start)
    if source.still:
        print(f"start pose: {start_pose_origin(source)}")
    result = extract(
        source,
        poses_for(args.poses, source.still),
        args.out,
        config_path=args.config,
        preset=args.preset,
        progress=not args.quiet,
    )
    s = result.stats
    print(
        f"{s['features']} lines from {s['beams']} beams ({s['preset']} preset, {s['poses']} poses); "
        f"per beam p50 {s['beam_time_p50_us']:.0f} us, p99 {s['beam_time_p99_us']:.0f} us; "
        f"{s['data_s']:.0f} s of data in {s['wall_s']:.2f} s ({s['realtime_factor']:.0f}x real time)"
    )
    print(
        f"outputs: {Path(result.out_dir or args.out).resolve()} (lines.jsonl, lines_world.png, extract.json)"
    )
    return 0
