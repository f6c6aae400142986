"""``sonarslam sweep``: Monte Carlo runs and parameter grids on Dask."""

from __future__ import annotations

import argparse

from sonarslam.slam.run.sweep import format_summary, load_grid_toml, parse_grid, parse_seeds, sweep


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
