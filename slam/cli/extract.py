"""``sonarslam extract``: the line features of a dataset with one pose source."""

from __future__ import annotations

import argparse
from dataclasses import replace
from pathlib import Path

from sonarslam.datasets.source import Dataset, open_dataset
from sonarslam.slam.run.extraction import extract


def command(args: argparse.Namespace) -> int:
    source: str | Dataset = args.source
    if args.start is not None or args.nav is not None or args.span is not None:
        opened = open_dataset(args.source, nav=args.nav, span_s=args.span)
        source = replace(opened, start_enu=args.start)
    result = extract(
        source,
        args.poses,
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
