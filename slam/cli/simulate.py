"""``sonarslam simulate``: a simulated run written in the marina layout."""

from __future__ import annotations

import argparse

from sonarslam.datasets.simulator import simulate
from sonarslam.slam.io.files import check_output_dir


def command(args: argparse.Namespace) -> int:
    check_output_dir(args.out)
    out = simulate(args.kind, seed=args.seed, out_dir=args.out, duration_s=args.duration)
    print(f"simulated {args.kind} (seed {args.seed}) written to {out}")
    return 0
