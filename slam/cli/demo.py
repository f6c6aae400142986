"""``sonarslam demo``: the main job of ``make run``."""

from __future__ import annotations

import argparse
from pathlib import Path

from sonarslam.slam.io.files import check_output_dir
from sonarslam.slam.run.demo import demo_source, main_job
from sonarslam.slam.run.run import results_table, smoothed_lines, summary_line


def command(args: argparse.Namespace) -> int:
    check_output_dir(args.out)
    source = demo_source(args.sim_duration)
    print(f"Running {source.description}.", flush=True)
    results = main_job(
        args.out, progress=not args.quiet, source=source, duration_s=args.sim_duration
    )
    if source.simulated:
        print(
            "\nResults (ATE against the simulator's truth, no alignment, then rigidly aligned;"
            " against its simulated GPS after):"
        )
    else:
        print("\nResults (ATE against GPS, no alignment):")
    for r in results:
        print("  " + summary_line(r.metrics))
        # the factor graph's offline estimate, decided again after the run (docs/offline.md)
        offline = f"{r.metrics['backend']} offline:"
        for line in smoothed_lines(r.metrics):
            if line.startswith(offline):
                print("  " + line)
    if source.simulated:
        print(
            "\nEvery trajectory against the simulator's truth, then against its simulated GPS"
            " (the whole run), as published (no alignment) and after a rigid SE(2) fit:\n"
        )
    else:
        print(
            "\nEvery trajectory against GPS, as published (no alignment) and after a rigid SE(2) fit:\n"
        )
    print(results_table(results))
    print("\nOutputs and pictures:")
    what = "the simulated GPS" if source.simulated else "GPS"
    print(
        f"  {Path(args.out).resolve()}  (*_trajectories.png: every estimate against"
        f" {'the truth' if source.simulated else 'GPS'}; *_scans_gps.png: the sonar map with"
        f" {what} poses)"
    )
    for r in results:
        if r.out_dir is not None:
            pics = ", ".join(p.name for p in sorted(r.out_dir.glob("*.png")))
            print(f"  {r.out_dir.resolve()}  ({pics})")
    return 0
