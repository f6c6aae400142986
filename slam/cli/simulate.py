"""``sonarslam simulate``: a simulated run written in the marina layout."""

from __future__ import annotations

import argparse

from sonarslam.datasets.simulator import KINDS, simulate
from sonarslam.slam.cli.common import EPILOG, Subparsers, number
from sonarslam.slam.io.files import check_output_dir


def add_parser(sub: Subparsers) -> None:
    p = sub.add_parser("simulate", help="simulate a run in the marina layout", epilog=EPILOG)
    p.add_argument(
        "kind",
        choices=list(KINDS),
        help="world: seed pool, harbour, random harbour, drift (1,800 s, drifting sensors),"
        " drawn (as drift, in a harbour and route drawn from the seed)",
    )
    p.add_argument(
        "--seed", type=number(int, 0, 2**32 - 1), default=0, help="random seed (default 0)"
    )
    p.add_argument("--out", required=True, help="output directory")
    p.add_argument(
        "--duration",
        type=number(float, 1.0, 1e6, low_open=True),
        default=None,
        help="seconds of simulated time (default per world)",
    )
    p.set_defaults(func=command)


def command(args: argparse.Namespace) -> int:
    check_output_dir(args.out)
    out = simulate(args.kind, seed=args.seed, out_dir=args.out, duration_s=args.duration)
    print(f"simulated {args.kind} (seed {args.seed}) written to {out}")
    return 0
