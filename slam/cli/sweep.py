"""``sonarslam sweep``: Monte Carlo runs and parameter grids on Dask."""

from __future__ import annotations

import argparse

from sonarslam.datasets.simulator import KINDS
from sonarslam.slam.cli.common import EPILOG, Subparsers, add_quiet, number
from sonarslam.slam.run.sweep import format_summary, load_grid_toml, parse_grid, parse_seeds, sweep


def add_parser(sub: Subparsers) -> None:
    p = sub.add_parser(
        "sweep",
        help="Monte Carlo runs and parameter grids on Dask: ATE and ANEES per back end",
        epilog=EPILOG,
    )
    p.add_argument("--seeds", default="0-9", help="seeds: 0-49, 3, or 0,2,5-7 (default 0-9)")
    p.add_argument(
        "--world",
        default="drawn",
        choices=list(KINDS),
        help="simulated world (default drawn: a harbour and route drawn per seed, 1,800 s with"
        " drifting sensors; drift and harbour: fixed layouts). Seeds >= 10000 are held back:"
        " never tune on them",
    )
    p.add_argument(
        "--backend",
        default="dr,ekf",
        help="comma list of back ends (default dr,ekf), e.g. ekf,isam2",
    )
    p.add_argument(
        "--grid",
        action="append",
        metavar="SCOPE.FIELD=V1,V2",
        help="a grid axis, e.g. ekf.association=jcbb,nn or extractor.min_votes=10,15 (repeatable)",
    )
    p.add_argument("--grid-file", default=None, help="TOML of grid axes ([grid] table of arrays)")
    p.add_argument(
        "--duration",
        type=number(float, 1.0, 1e6, low_open=True),
        default=None,
        help="simulated seconds (default per world)",
    )
    p.add_argument("--out", required=True, help="output directory")
    p.add_argument(
        "--cache", default=None, help="simulated folders, reused across sweeps (default OUT/sim)"
    )
    p.add_argument(
        "--scheduler",
        default=None,
        help="address of a Dask scheduler (default: a local cluster; 'synchronous': no Dask)",
    )
    p.add_argument(
        "--workers",
        type=number(int, 1, 256),
        default=2,
        help="local cluster processes (default 2)",
    )
    p.add_argument(
        "--calibrate",
        action="store_true",
        help="calibrate each seed's sonar GPS-free first (range offset, a line's systematic error:"
        " calibrate --range-offset, --line-noise) and run with it",
    )
    add_quiet(p)
    p.set_defaults(func=command)


def command(args: argparse.Namespace) -> int:
    grid = load_grid_toml(args.grid_file) if args.grid_file else {}
    grid.update(parse_grid(args.grid or []))
    result = sweep(
        parse_seeds(args.seeds),
        [b.strip() for b in args.backend.split(",") if b.strip()],
        args.out,
        grid=grid,
        world=args.world,
        duration_s=args.duration,
        cache_dir=args.cache,
        scheduler=args.scheduler,
        n_workers=args.workers,
        progress=not args.quiet,
        calibrate=args.calibrate,
    )
    failed = int((result.table["error"].fillna("") != "").sum()) if len(result.table) else 0
    print(format_summary(result.summary, brief=True))
    print()
    print(result.spread)
    print(
        f"{len(result.table)} runs ({failed} failed) in {result.wall_s:.1f} s; "
        f"outputs: {result.out_dir.resolve()} ({', '.join(p.name for p in result.files.values())})"
    )
    return 0
