"""``sonarslam plot-scans``: the sonar bins projected into the world with a pose source."""

from __future__ import annotations

import argparse
from dataclasses import replace

from sonarslam.datasets.source import open_dataset
from sonarslam.features.projection import project_beams
from sonarslam.slam.cli.common import poses_for
from sonarslam.slam.eval.truth import truth_walls
from sonarslam.slam.io.files import check_output_file, make_output_dir, write_atomic
from sonarslam.slam.io.maps import plot_scans
from sonarslam.slam.run.presets import map_min_intensity
from sonarslam.slam.run.sources import pose_source_by_name, start_pose_origin


def command(args: argparse.Namespace) -> int:
    out = check_output_file(args.out, ".png")
    dataset = replace(
        open_dataset(args.source, nav=args.nav, span_s=args.span), start_enu=args.start
    )
    name = poses_for(args.poses, dataset.still)
    poses = pose_source_by_name(dataset, name)
    beams = dataset.nav_beams()
    min_intensity = map_min_intensity(beams) if args.min_intensity is None else args.min_intensity
    points, _ = project_beams(
        beams, dataset.config.sonar, dataset.config.sonar_mounting, poses, min_intensity
    )
    make_output_dir(out.parent)
    title = f"{dataset.name}: sonar bins projected with {name} poses"
    if dataset.still:
        title += " (no navigation: a still head)"
        print(f"start pose: {start_pose_origin(dataset)}")
    walls = truth_walls(dataset) if dataset.truth and "walls_m" in dataset.truth else None
    write_atomic(out, lambda p: plot_scans(p, points, {name: poses}, title, walls))
    print(f"{points.shape[0]} bins projected with {name} poses; picture: {out.resolve()}")
    return 0
