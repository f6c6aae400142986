"""``sonarslam plot-scans``: the sonar bins projected into the world with a pose source."""

from __future__ import annotations

import argparse
from pathlib import Path

from datasets.source import open_dataset
from features.projection import project_beams
from slam.cli.common import EPILOG, Subparsers, add_poses, add_source
from slam.eval.truth import truth_walls
from slam.io.maps import plot_scans
from slam.run.presets import map_min_intensity
from slam.run.sources import pose_source_by_name


def add_parser(sub: Subparsers) -> None:
    p = sub.add_parser(
        "plot-scans", help="project the sonar bins into the world and draw them", epilog=EPILOG
    )
    add_source(p)
    add_poses(p, "gps")
    p.add_argument("--out", default="out/scans.png", help="PNG file (default out/scans.png)")
    p.add_argument(
        "--min-intensity",
        type=int,
        default=None,
        help="smallest intensity drawn, 0-255 (default: every bin of thresholded beams, the "
        "extractor's threshold for raw beams)",
    )
    p.set_defaults(func=command)


def command(args: argparse.Namespace) -> int:
    dataset = open_dataset(args.source)
    poses = pose_source_by_name(dataset, args.poses)
    beams = dataset.nav_beams()
    min_intensity = map_min_intensity(beams) if args.min_intensity is None else args.min_intensity
    points, _ = project_beams(
        beams, dataset.config.sonar, dataset.config.sonar_mounting, poses, min_intensity
    )
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    plot_scans(
        out,
        points,
        {args.poses: poses},
        f"{dataset.name}: sonar bins projected with {args.poses} poses",
        truth_walls(dataset) if dataset.truth and "walls_m" in dataset.truth else None,
    )
    print(f"{points.shape[0]} bins projected; picture: {out.resolve()}")
    return 0
