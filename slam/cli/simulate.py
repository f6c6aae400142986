"""``sonarslam simulate``: a simulated run written in the marina layout, as a ROS bag, or as a
Ping Viewer ``.bin`` with its navigation (a ``nav.bag``, or a BlueROV2's own logs)."""

from __future__ import annotations

import argparse
import shutil
import tempfile
import warnings
from pathlib import Path

from sonarslam.datasets.config import dump_dataset_config
from sonarslam.datasets.errors import DataWarning
from sonarslam.datasets.rosbag import bag_config, write_bag
from sonarslam.datasets.simulator import simulate
from sonarslam.datasets.simulator.bluerov import simulate_bluerov
from sonarslam.datasets.simulator.ping360 import PERSIAN_ZERO, Ping360Defects, simulate_ping360
from sonarslam.datasets.simulator.writer import drop_gps
from sonarslam.datasets.source import open_dataset
from sonarslam.settings import SettingError
from sonarslam.slam.io.files import check_output_dir


def command(args: argparse.Namespace) -> int:
    check_output_dir(args.out)
    for flag, given in (
        ("--first-ranges", args.first_ranges),
        ("--persian-digits", args.persian_digits),
        ("--no-nav", args.no_nav),
    ):
        if given and not args.ping360:
            raise SettingError(flag, "a Ping360 log's defect: give --ping360 too")
    if args.bluerov is not None:
        if args.bag is not None or args.ping360:
            raise SettingError("--bluerov", "a BlueROV2 run is a .bin and its logs: no --bag")
        log, navs = simulate_bluerov(
            args.kind,
            seed=args.seed,
            out_dir=args.out,
            nav=args.bluerov,
            duration_s=args.duration,
            gps=not args.no_gps,
        )
        print(
            f"simulated {args.kind} (seed {args.seed}) written as a BlueROV2 logs it: {log}, with"
            f" {', '.join(str(n) for n in navs)} ({args.bluerov}) and sonarslam.toml"
            f" ([ping360] nav); run it: sonarslam run {log}"
        )
        return 0
    if args.ping360:
        if args.bag is not None:
            raise SettingError("--ping360", "a Ping360 run's navigation is a ROS 1 bag: no --bag")
        defects = Ping360Defects(
            zero_digit=PERSIAN_ZERO if args.persian_digits else "0",
            first_ranges_m=args.first_ranges,
            nav=not args.no_nav,
        )
        log = simulate_ping360(
            args.kind,
            seed=args.seed,
            out_dir=args.out,
            duration_s=args.duration,
            gps=not args.no_gps,
            defects=defects,
        )
        nav = (
            f"with {log.parent / 'nav.bag'} and sonarslam.toml ([ping360] nav)"
            if defects.nav
            else "without navigation (a still head), with sonarslam.toml"
        )
        print(
            f"simulated {args.kind} (seed {args.seed}) written as a Ping360 logs it: {log}, {nav}"
        )
        return 0
    if (
        args.bag in ("mcap", "sqlite3")
        and Path(args.out).exists()
        and any(Path(args.out).iterdir())
    ):
        raise SettingError(
            "--out", f"{args.out} is not empty: a ROS 2 bag is a directory of its own"
        )
    if args.preset is not None and args.bag is None:
        raise SettingError("--preset", "a preset is the shape of a bag: give --bag too")
    without = " without GPS" if args.no_gps else ""
    if args.bag is None:
        out = simulate(args.kind, seed=args.seed, out_dir=args.out, duration_s=args.duration)
        if args.no_gps:
            drop_gps(out)
        print(f"simulated {args.kind} (seed {args.seed}) written to {out}{without}")
        return 0
    with tempfile.TemporaryDirectory() as tmp:
        layout = simulate(
            args.kind, seed=args.seed, out_dir=Path(tmp) / "run", duration_s=args.duration
        )
        if args.no_gps:
            drop_gps(layout)
        with warnings.catch_warnings():  # the sensors' gaps are the simulator's own: said below
            warnings.simplefilter("ignore", DataWarning)
            dataset = open_dataset(layout)
        out = Path(args.out)
        if args.bag == "ros1":
            out.mkdir(parents=True, exist_ok=True)
            prefix = next(Path(layout).glob("*_DVL.log")).name.removesuffix("_DVL.log")
            bag = write_bag(dataset, out / f"{prefix}.bag", "ros1", args.preset)
        else:
            if out.exists():
                out.rmdir()  # an empty directory (check_output_dir): rosbags creates its own
            bag = write_bag(dataset, out, args.bag, args.preset)
        shutil.copy(Path(layout) / "truth.json", out / "truth.json")
        toml = dump_dataset_config(bag_config(dataset.config))  # REP-103 angles
        if args.preset is not None:  # the mountings are the bag's transforms
            toml = _without_mountings(toml)
        (out / "sonarslam.toml").write_text(toml, encoding="utf-8")
    print(f"simulated {args.kind} (seed {args.seed}) written as a {args.bag} bag{without}: {bag}")
    return 0


def _without_mountings(toml: str) -> str:
    """A ``sonarslam.toml``'s text without its ``[mounting.*]`` tables."""
    out, skip = [], False
    for line in toml.splitlines():
        if line.startswith("["):
            skip = line.startswith("[mounting.")
        if not skip:
            out.append(line)
    return "\n".join(out) + "\n"
