"""The ``sonarslam`` command: parse, call a library function, print. Known errors: one line, exit 1."""

from __future__ import annotations

import argparse
import math
import sys
import warnings
from collections.abc import Sequence
from pathlib import Path

from datasets.errors import DataError, DataWarning

__all__ = ["main", "build_parser"]

EPILOG = (
    "Data: a SOURCE is a directory in the marina layout (see README) or the named source 'marina', "
    "found under $SONARSLAM_DATA/marina."
)


def _cmd_simulate(args: argparse.Namespace) -> int:
    from datasets.simulator import simulate

    out = simulate(args.kind, seed=args.seed, out_dir=args.out, duration_s=args.duration)
    print(f"simulated {args.kind} (seed {args.seed}) written to {out}")
    return 0


def _cmd_run(args: argparse.Namespace) -> int:
    from slam.run.presets import parse_settings
    from slam.run.run import run, summary_line

    result = run(
        args.source,
        args.backend,
        args.out,
        progress=not args.quiet,
        batch=args.batch,
        config=args.config,
        settings=parse_settings(args.set),
    )
    print(summary_line(result.metrics))
    print(
        f"outputs: {result.out_dir.resolve()} (trajectory.tum, ground_truth.tum, metrics.json, report.png)"
    )
    return 0


def _cmd_demo(args: argparse.Namespace) -> int:
    from slam.run.run import main_job, summary_line

    results = main_job(args.out, progress=not args.quiet)
    print("\nResults (ATE against GPS, no alignment):")
    for r in results:
        print("  " + summary_line(r.metrics))
    print("\nOutputs and pictures:")
    print(f"  {Path(args.out).resolve()}  (*_scans_gps.png: the sonar map with GPS poses)")
    for r in results:
        pics = ", ".join(p.name for p in sorted(r.out_dir.glob("*.png")))
        print(f"  {r.out_dir.resolve()}  ({pics})")
    return 0


def _cmd_plot_scans(args: argparse.Namespace) -> int:
    from datasets.source import open_dataset
    from features.projection import project_beams
    from slam.io.plots import plot_scans
    from slam.run.run import map_min_intensity, pose_source_by_name

    dataset = open_dataset(args.source)
    poses = pose_source_by_name(dataset, args.poses)
    min_intensity = map_min_intensity(dataset) if args.min_intensity is None else args.min_intensity
    points, _ = project_beams(
        dataset.nav_beams(),
        dataset.config.sonar,
        dataset.config.sonar_mounting,
        poses,
        min_intensity,
    )
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    plot_scans(
        out,
        points,
        {args.poses: poses},
        f"{dataset.name}: sonar bins projected with {args.poses} poses",
    )
    print(f"{points.shape[0]} bins projected; picture: {out.resolve()}")
    return 0


def _cmd_extract(args: argparse.Namespace) -> int:
    from slam.run.extraction import extract

    result = extract(
        args.source,
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


def _cmd_calibrate(args: argparse.Namespace) -> int:
    from datasets.source import open_dataset
    from slam.run.calibration import calibrate_ahrs_yaw, calibrate_sonar_yaw
    from slam.run.run import pose_source_by_name

    dataset = open_dataset(args.source)
    if args.ahrs_deviation:
        from slam.backends.ekf import EkfConfig, LineEkf
        from slam.run.calibration import calibrate_ahrs_deviation
        from slam.run.closed_loop import run_closed_loop
        from slam.run.run import default_extractor_config

        def run(ds):  # noqa: ANN001, ANN202
            mount = ds.config.sonar_mounting
            return run_closed_loop(
                ds,
                lambda t, p, c: LineEkf(t, p, c, mount, EkfConfig()),
                default_extractor_config(ds),
                progress=False,
            )

        b0, c0 = (math.degrees(v) for v in dataset.config.ahrs_deviation_rad)
        print(
            f"AHRS deviation from the EKF's line re-observations (GPS-free), from [{b0:.2f}, {c0:.2f}] deg:"
        )
        steps = calibrate_ahrs_deviation(dataset, run, iterations=args.iterations)
        for k, (dev, n) in enumerate(steps, start=1):
            print(
                f"  iteration {k}: [{math.degrees(dev[0]):.2f}, {math.degrees(dev[1]):.2f}] deg ({n} lines)"
            )
        b, c = (math.degrees(v) for v in steps[-1][0])
        print(f"put it under [motion] as ahrs_deviation_deg = [{b:.2f}, {c:.2f}]")
        return 0
    if args.ahrs:
        fit = calibrate_ahrs_yaw(dataset)
        amp = math.degrees(math.hypot(*fit.harmonics_rad[:2]))
        print(
            f"AHRS mounting yaw from the DVL compass (GPS-free): "
            f"{math.degrees(fit.ahrs_yaw_rad):.2f} deg (configured: "
            f"{math.degrees(dataset.config.ahrs_mounting.yaw_rad):.2f} deg); DVL compass - AHRS "
            f"yaw = {math.degrees(fit.offset_rad):.2f} deg over headings (time mean "
            f"{math.degrees(fit.time_mean_rad):.2f} deg), deviation {amp:.1f} deg, residual sd "
            f"{math.degrees(fit.residual_sd_rad):.2f} deg; put it under [mounting.ahrs] yaw_deg"
        )
        return 0
    poses = pose_source_by_name(dataset, args.poses)
    result = calibrate_sonar_yaw(dataset, poses, window_s=args.window)
    current = math.degrees(dataset.config.sonar_mounting.yaw_rad)
    print(
        f"sonar mounting yaw with {args.poses} poses: {math.degrees(result.best_yaw_rad):.2f} deg "
        f"(configured: {current:.2f} deg); put it under [mounting.sonar] yaw_deg in sonarslam.toml"
    )
    return 0


def _cmd_info(args: argparse.Namespace) -> int:
    from datasets.source import open_dataset

    d = open_dataset(args.source)
    t0, t1 = d.nav_span_s
    print(f"{d.name}: {d.root}")
    print(f"  sonar beams {len(d.beams)} ({len(d.nav_beams())} inside the navigation span)")
    print(f"  DVL rows {d.dvl.t.size} ({int((~d.dvl.valid).sum())} without bottom lock)")
    print(f"  AHRS rows {d.attitude.t.size}; GPS fixes {0 if d.gps is None else d.gps.t.size}")
    print(f"  navigation span {t1 - t0:.1f} s; head {d.config.sonar}")
    for name in ("sonar", "dvl", "ahrs"):
        m = getattr(d.config, f"{name}_mounting")
        print(
            f"  {name} mounting x={m.x_m} m y={m.y_m} m yaw={math.degrees(m.yaw_rad):.2f} deg ({m.source})"
        )
    b, c = (math.degrees(v) for v in d.config.ahrs_deviation_rad)
    print(
        f"  AHRS deviation B={b:.2f} C={c:.2f} deg (taken off: B sin(yaw) + C cos(yaw)); heading"
        f" between AHRS samples from the {d.config.yaw_rate_source}"
    )
    from slam.run.sources import dvl_quality

    n, dq = d.config.noise, dvl_quality(d)
    print(
        f"  DVL scatter over {n.dvl_scatter_window_s or 60.0:g} s (m/s): "
        + ", ".join(f"p{p} {dq[f'dvl_scatter_p{p}_mps']:.3f}" for p in (10, 50, 90, 99))
    )
    if n.dvl_scatter_window_s > 0:
        first = dq["dvl_excess_from_s"]
        print(
            f"  DVL sigma {n.dvl_sigma_mps} m/s, plus the scatter's excess over"
            f" {n.dvl_nominal_scatter_mps} m/s: {dq['dvl_excess_s']:.0f} s of the run"
            + (f", first at {first:.0f} s" if first >= 0 else "")
        )
    else:
        print(f"  DVL sigma {n.dvl_sigma_mps} m/s (the scatter's excess is not added)")
    return 0


def _cmd_report(args: argparse.Namespace) -> int:
    from slam.run.report import report

    result = report(
        args.dirs,
        args.out,
        rpe_delta_m=args.rpe_delta,
        align=args.align,
        open_sources=not args.no_source,
    )
    for row in result.rows:
        if row.get("ate_n") is not None:
            print(
                f"{row['method']} [{row['run']}, {row['dataset']}]: ATE mean {row['ate_mean_m']:.2f} m, "
                f"rmse {row['ate_rmse_m']:.2f}; evo APE rmse {row['evo_ape_rmse_m']:.2f} m"
                + (
                    f"; pose NEES mean {row['nees_mean']:.2f}"
                    if row.get("nees_mean") is not None
                    else ""
                )
            )
    print(f"report: {result.path.resolve()} ({len(result.figures)} figures)")
    return 0


def _cmd_sweep(args: argparse.Namespace) -> int:
    from slam.run.sweep import format_summary, load_grid_toml, parse_grid, parse_seeds, sweep

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
    )
    failed = int((result.table["error"].fillna("") != "").sum()) if len(result.table) else 0
    print(format_summary(result.summary))
    print(
        f"{len(result.table)} runs ({failed} failed) in {result.wall_s:.1f} s; "
        f"outputs: {result.out_dir.resolve()} ({', '.join(p.name for p in result.files.values())})"
    )
    return 0


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="sonarslam",
        description="Line features with honest uncertainty from MSIS sonar, and SLAM with them.",
        epilog=EPILOG,
    )
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")

    p = sub.add_parser("simulate", help="simulate a run in the marina layout", epilog=EPILOG)
    p.add_argument(
        "kind",
        choices=["pool", "harbour", "random"],
        help="world: seed pool, harbour, random harbour",
    )
    p.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    p.add_argument("--out", required=True, help="output directory")
    p.add_argument(
        "--duration", type=float, default=None, help="seconds of simulated time (default per world)"
    )
    p.set_defaults(func=_cmd_simulate)

    p = sub.add_parser("run", help="run a back end and evaluate it against GPS", epilog=EPILOG)
    p.add_argument("source", help="dataset directory or 'marina'")
    p.add_argument(
        "--backend", default="dr", help="dr (dead reckoning), gps (GPS+AHRS), ekf, isam2"
    )
    p.add_argument("--out", required=True, help="output directory")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.add_argument(
        "--batch",
        action="store_true",
        help="isam2 only: a final batch Levenberg-Marquardt pass (trajectory_batch.tum, ate_*_batch_m)",
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
    p.set_defaults(func=_cmd_run)

    p = sub.add_parser(
        "plot-scans", help="project the sonar bins into the world and draw them", epilog=EPILOG
    )
    p.add_argument("source", help="dataset directory or 'marina'")
    p.add_argument(
        "--poses", default="gps", help="pose source: gps (GPS+AHRS), dr, truth (simulated only)"
    )
    p.add_argument("--out", default="out/scans.png", help="PNG file (default out/scans.png)")
    p.add_argument(
        "--min-intensity",
        type=int,
        default=None,
        help="smallest intensity drawn, 0-255 (default: every bin of thresholded beams, the "
        "extractor's threshold for raw beams)",
    )
    p.set_defaults(func=_cmd_plot_scans)

    p = sub.add_parser(
        "extract", help="extract line features with a pose source and draw them", epilog=EPILOG
    )
    p.add_argument("source", help="dataset directory or 'marina'")
    p.add_argument(
        "--poses",
        default="gps",
        choices=["gps", "dr", "truth"],
        help="pose source: gps (GPS+AHRS, default), dr, truth (simulated only)",
    )
    p.add_argument("--out", required=True, help="output directory")
    p.add_argument(
        "--config", default=None, help="TOML of extractor settings over the preset ([extractor])"
    )
    p.add_argument(
        "--preset",
        default=None,
        choices=["marina", "default"],
        help="starting settings (default: marina for thresholded beams, else default)",
    )
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=_cmd_extract)

    p = sub.add_parser(
        "demo",
        help="the main job (make run): both closed loops and dead reckoning on the marina or a simulated harbour",
        epilog=EPILOG,
    )
    p.add_argument("--out", default="out", help="output directory (default out)")
    p.add_argument("--quiet", action="store_true", help="no progress bars")
    p.set_defaults(func=_cmd_demo)

    p = sub.add_parser(
        "calibrate",
        help="sonar mounting yaw by map sharpness; --ahrs: AHRS yaw from the DVL compass",
        epilog=EPILOG,
    )
    p.add_argument("source", help="dataset directory or 'marina'")
    p.add_argument("--poses", default="dr", help="pose source (default dr: GPS-free)")
    p.add_argument("--window", type=float, default=120.0, help="entropy window (s, default 120)")
    p.add_argument(
        "--ahrs",
        action="store_true",
        help="the AHRS mounting yaw from the DVL's own compass instead (GPS-free)",
    )
    p.add_argument(
        "--ahrs-deviation",
        action="store_true",
        help="the AHRS heading's deviation B sin(yaw) + C cos(yaw) from the sonar lines of EKF"
        " closed loops instead (GPS-free, ~20 s per iteration on the marina)",
    )
    p.add_argument(
        "--iterations", type=int, default=4, help="closed loops for --ahrs-deviation (default 4)"
    )
    p.set_defaults(func=_cmd_calibrate)

    p = sub.add_parser("info", help="what a dataset holds", epilog=EPILOG)
    p.add_argument("source", help="dataset directory or 'marina'")
    p.set_defaults(func=_cmd_info)

    p = sub.add_parser(
        "report",
        help="side-by-side report of run directories: table, maps, errors, NEES",
        epilog=EPILOG,
    )
    p.add_argument("dirs", nargs="+", help="run directories written by 'sonarslam run'")
    p.add_argument("--out", required=True, help="output directory (report.md and PNGs)")
    p.add_argument(
        "--rpe-delta", type=float, default=10.0, help="path length of evo's RPE (m, default 10)"
    )
    p.add_argument(
        "--align", action="store_true", help="Umeyama-align before evo's APE/RPE (default none)"
    )
    p.add_argument(
        "--no-source",
        action="store_true",
        help="do not re-open the runs' datasets (no reprojected map, no truth)",
    )
    p.set_defaults(func=_cmd_report)

    p = sub.add_parser(
        "sweep",
        help="Monte Carlo runs and parameter grids on Dask: ATE and ANEES per back end",
        epilog=EPILOG,
    )
    p.add_argument("--seeds", default="0-9", help="seeds: 0-49, 3, or 0,2,5-7 (default 0-9)")
    p.add_argument(
        "--world", default="harbour", choices=["harbour", "random", "pool"], help="simulated world"
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
        "--duration", type=float, default=None, help="simulated seconds (default per world)"
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
    p.add_argument("--workers", type=int, default=2, help="local cluster processes (default 2)")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=_cmd_sweep)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    with warnings.catch_warnings():
        warnings.simplefilter("always", DataWarning)
        warnings.formatwarning = lambda msg, *a, **k: f"warning: {msg}\n"  # type: ignore[assignment]
        try:
            return int(args.func(args))
        except (DataError, ValueError, FileNotFoundError) as exc:
            print(f"sonarslam {args.command}: error: {exc}", file=sys.stderr)
            return 1


if __name__ == "__main__":
    raise SystemExit(main())
