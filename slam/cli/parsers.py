"""What the command line accepts: one parser per command, built from argparse and
:mod:`sonarslam.slam.cli.common` alone, so that ``sonarslam --help`` and ``sonarslam COMMAND
--help`` answer without importing the library; :data:`COMMANDS` names the module that runs each
(loaded by :mod:`sonarslam.slam.cli.main` only when the command runs).

The choices offered here are the library's registries spelled out (the registries import the
back ends and the simulator); ``tests/test_cli.py`` checks that they are the same.
"""

from __future__ import annotations

import argparse
from collections.abc import Callable

from sonarslam.slam.cli.common import (
    EPILOG,
    Subparsers,
    add_config_and_set,
    add_poses,
    add_quiet,
    add_source,
    add_start,
    add_topics,
    number,
    parse_loop,
)

__all__ = [
    "COMMANDS",
    "BACKENDS",
    "BAG_KINDS",
    "BLUEROV_NAV_KINDS",
    "EXTRACTOR_PRESETS",
    "WORLDS",
    "SIM_DURATION_S",
]

#: ``--backend``: :func:`sonarslam.slam.run.run.backend_names` (the baselines, then the closed
#: loops of :data:`sonarslam.slam.backends.registry.BACKENDS`).
BACKENDS = ("dr", "gps", "ekf", "isam2")
#: ``--preset``: :data:`sonarslam.slam.run.presets.EXTRACTOR_PRESETS`, sorted.
EXTRACTOR_PRESETS = ("default", "marina", "marina-fit", "marina-seed")
#: The simulated worlds: :data:`sonarslam.datasets.simulator.KINDS`.
WORLDS = ("pool", "harbour", "random", "drift", "drawn")
#: ``simulate --bag``: :data:`sonarslam.datasets.rosbag.BAG_KINDS`.
BAG_KINDS = ("ros1", "mcap", "sqlite3")
#: ``simulate --bluerov``: :data:`sonarslam.datasets.simulator.bluerov.NAV_KINDS`.
BLUEROV_NAV_KINDS = ("tlog", "dataflash", "dvl_json", "dvl_json_v1", "qgc_csv")
#: ``demo --sim-duration``'s default: :data:`sonarslam.slam.run.demo.SIM_DURATION_S` (s).
SIM_DURATION_S = 600.0


def _simulate(sub: Subparsers) -> argparse.ArgumentParser:
    p = sub.add_parser(
        "simulate",
        help="simulate a run and write it in the marina layout, as a ROS bag (--bag), or as a"
        " Ping Viewer .bin with its navigation (--ping360) or a BlueROV2's logs (--bluerov)",
    )
    p.add_argument(
        "kind",
        choices=WORLDS,
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
    p.add_argument(
        "--bag",
        choices=BAG_KINDS,
        default=None,
        help="write a ROS bag instead of the marina layout: ros1 (OUT/<run>.bag), mcap or sqlite3"
        " (OUT is the ROS 2 bag directory); sonarslam.toml and truth.json go with it",
    )
    p.add_argument(
        "--preset",
        choices=("caves",),
        default=None,
        help="with --bag: in the shape of the Girona caves data set (its topics, its LinkQuest DVL"
        " message, the sensor offsets on /tf, no GPS); the sonarslam.toml written has no"
        " [mounting.*] tables (the transforms give them)",
    )
    p.add_argument(
        "--no-gps",
        action="store_true",
        help="leave the GPS out, whatever the output: the layout without its *_DGPS.log, a bag"
        " (--bag, any --preset) without a NavSatFix topic, a Ping360 run's nav.bag likewise; runs"
        " on it are measured against truth.json and their loops (docs/data.md, 'Without GPS')",
    )
    p.add_argument(
        "--bluerov",
        choices=BLUEROV_NAV_KINDS,
        default=None,
        metavar="NAV",
        help="write the run as a BlueROV2 logs it: a Ping Viewer OUT/<start>.bin and the"
        " navigation as NAV, with its writer's known defects (corrupt chunks, json_v1's relative"
        " times, QGroundControl's 1 Hz rounded CSV): tlog (QGroundControl .tlog: ATTITUDE, the"
        " DVL's VISION_POSITION_DELTA, the autopilot's LOCAL_POSITION_NED, an Underwater GPS's"
        " GPS_INPUT), dataflash (an ArduSub .BIN), dvl_json (the A50's json_v3), dvl_json_v1"
        " (json_v1 and an ATTITUDE-only .tlog for the heading), qgc_csv (QGroundControl's CSV"
        " export); sonarslam.toml's [ping360] nav names it (choices: %(choices)s)",
    )
    p.add_argument(
        "--ping360",
        action="store_true",
        help="write the run as a Ping360 logs it instead: a Ping Viewer OUT/<start>.bin (a"
        " Ping360-shaped head: whole gradians, 25 ns sample periods; its records split"
        " mid-message as Ping Viewer's serial link delivers them) and OUT/nav.bag",
    )
    p.add_argument(
        "--first-ranges",
        type=_ranges,
        default=(),
        metavar="M,M",
        help="with --ping360: the log starts at these ranges (m), 3 s each, before the world's"
        " head (e.g. 2,15: Ping Viewer opens at 2 m), each beam rendered at its range with"
        " 1200 samples; the log is read as segments",
    )
    p.add_argument(
        "--persian-digits",
        action="store_true",
        help="with --ping360: the file name and the records' stamps in Extended Arabic-Indic"
        " digits, as Ping Viewer on a Persian-locale Windows writes them",
    )
    p.add_argument(
        "--no-nav",
        action="store_true",
        help="with --ping360: the .bin alone, no nav.bag (a tank test; read as a still head)",
    )
    add_quiet(p, progress=False)
    return p


def _ranges(text: str) -> tuple[float, ...]:
    """``M,M,...``: ranges (m); an argparse ``type``."""
    try:
        return tuple(float(number(float, 0.75, 100.0)(v.strip())) for v in text.split(","))
    except argparse.ArgumentTypeError as exc:
        raise argparse.ArgumentTypeError(f"ranges M,M in m, 0.75-100: {exc}") from None


def _run(sub: Subparsers) -> argparse.ArgumentParser:
    p = sub.add_parser(
        "run",
        help="run a back end and evaluate it against GPS (and the truth on simulated data)",
        epilog=EPILOG,
    )
    add_source(p, loop=True)
    p.add_argument(
        "--backend",
        default="dr",
        choices=BACKENDS,
        help="dr (dead reckoning), gps (GPS+AHRS), ekf, isam2 (default dr)",
    )
    p.add_argument("--out", required=True, help="output directory")
    add_start(p)
    add_topics(p)
    p.add_argument(
        "--loop",
        type=parse_loop,
        action="append",
        default=[],
        metavar="T0,T1",
        help="the vehicle was at one place at T0 and T1 (s from the start of the navigation),"
        " repeatable: the loop-closure error of the run and of dead reckoning there"
        " (metrics.json loop_*); without GPS, loops are also found (slam/eval/loops.py)",
    )
    add_quiet(p)
    p.add_argument(
        "--batch",
        action="store_true",
        help="isam2 only: a final batch Levenberg-Marquardt pass (isam2_batch.tum, ate_*_batch_m);"
        " isam2 also makes its offline estimate after every run (isam2_offline.tum: every revisit"
        " and line decided again with hindsight, about a minute on the marina;"
        " --set isam2.offline=false turns it off, docs/offline.md)",
    )
    add_config_and_set(p)
    p.add_argument(
        "--strict",
        action="store_true",
        help="exit 1 when the health monitor finds the closed loop inconsistent with its own"
        " model (metrics.json health_*; the outputs are written all the same)",
    )
    return p


def _plot_scans(sub: Subparsers) -> argparse.ArgumentParser:
    p = sub.add_parser(
        "plot-scans", help="project the sonar bins into the world and draw them", epilog=EPILOG
    )
    add_source(p)
    add_poses(p, None)
    p.add_argument("--out", default="out/scans.png", help="PNG file (default out/scans.png)")
    p.add_argument(
        "--min-intensity",
        type=number(int, 0, 255),
        default=None,
        help="smallest intensity drawn, 0-255 (default: every bin of thresholded beams, the "
        "extractor's threshold for raw beams)",
    )
    add_start(p)
    add_quiet(p, progress=False)
    return p


def _extract(sub: Subparsers) -> argparse.ArgumentParser:
    p = sub.add_parser(
        "extract", help="extract line features with a pose source and draw them", epilog=EPILOG
    )
    add_source(p)
    add_poses(p, None)
    p.add_argument("--out", required=True, help="output directory")
    p.add_argument(
        "--config", default=None, help="TOML of extractor settings over the preset ([extractor])"
    )
    p.add_argument(
        "--preset",
        default=None,
        choices=EXTRACTOR_PRESETS,
        help="extractor preset (slam/run/presets.py; default: marina for thresholded beams, "
        "default for raw ones, as the closed loops)",
    )
    add_start(p)
    add_quiet(p)
    return p


def _demo(sub: Subparsers) -> argparse.ArgumentParser:
    p = sub.add_parser(
        "demo",
        help="the main job (make run): both closed loops and dead reckoning on the marina or, "
        "without it, a simulated harbour",
        epilog="Data: the marina is found under $SONARSLAM_DATA/marina; without it the demo"
        " simulates a harbour (--sim-duration).",
    )
    p.add_argument("--out", default="out", help="output directory (default out)")
    p.add_argument(
        "--sim-duration",
        type=float,
        default=SIM_DURATION_S,
        help=f"length of the simulated harbour when there is no marina (s, default {SIM_DURATION_S:g})",
    )
    add_quiet(p)
    return p


def _calibrate(sub: Subparsers) -> argparse.ArgumentParser:
    p = sub.add_parser(
        "calibrate",
        help="GPS-free calibrations: sonar yaw by map sharpness; --time-offset, --ahrs,"
        " --ahrs-deviation, --range-offset, --line-noise",
        epilog=EPILOG,
    )
    add_source(p)
    add_poses(p, "dr", ": GPS-free")
    p.add_argument(
        "--window",
        type=number(float, 0.0, 86400.0, low_open=True),
        default=None,
        help="entropy window (s, default 120; 60 for --time-offset)",
    )
    p.add_argument(
        "--accept-large-yaw",
        action="store_true",
        help="write a sonar yaw found more than 45 deg from a configured (given) one: only"
        " after checking the DVL's and AHRS's mountings, which map sharpness cannot tell from"
        " the sonar's (docs/calibration.md, its section When it refuses)",
    )
    p.add_argument(
        "--time-offset",
        action="store_true",
        help="the sonar clock offset by map sharpness instead: +-3 s around the configured"
        " one (GPS-free with the default --poses dr; [sonar] time_offset_s)",
    )
    p.add_argument(
        "--ahrs",
        action="store_true",
        help="the AHRS mounting yaw from the DVL's own compass instead (GPS-free)",
    )
    p.add_argument(
        "--ahrs-deviation",
        action="store_true",
        help="the AHRS heading's deviation B sin(yaw) + C cos(yaw) from the sonar lines of EKF"
        " closed loops instead (GPS-free; one closed loop per iteration)",
    )
    p.add_argument(
        "--iterations",
        type=number(int, 1, 100),
        default=4,
        help="closed loops for --ahrs-deviation (default 4)",
    )
    p.add_argument(
        "--range-offset",
        action="store_true",
        help="the range offset of the kept echoes from the beams' rising edges instead"
        " (GPS-free; [sonar] range_offset_m)",
    )
    p.add_argument(
        "--line-noise",
        action="store_true",
        help="a line's systematic error from pairs of lines of one wall seen 14-30 s apart with"
        " dead-reckoning poses instead (GPS-free; [noise] line_sigma_rho_m, line_sigma_theta_deg);"
        " with --range-offset too, the lines are measured with the offset just found",
    )
    p.add_argument(
        "--config",
        metavar="TOML",
        help="a partial sonarslam.toml over the dataset's own (e.g. [sonar] range_offset_m), as"
        " for run",
    )
    p.add_argument(
        "--write",
        metavar="TOML",
        help="write the dataset's calibration with the value(s) found to this sonarslam.toml"
        " (every key; an existing file is replaced)",
    )
    add_start(p)
    add_quiet(p)
    return p


def _info(sub: Subparsers) -> argparse.ArgumentParser:
    p = sub.add_parser(
        "info",
        help="what a dataset holds, every setting with its unit and source; of a navigation log"
        " alone (a .tlog, a dataflash .bin, a DVL A50 JSON log, a QGroundControl CSV): its"
        " messages, rates, spans and gaps, and which stream would be the odometry and heading",
        epilog=EPILOG,
    )
    add_source(p)
    add_topics(p)
    add_config_and_set(p)
    add_quiet(p, progress=False)
    return p


def _report(sub: Subparsers) -> argparse.ArgumentParser:
    p = sub.add_parser(
        "report",
        help="side-by-side report of run directories: table, maps, errors, NEES",
    )
    p.add_argument("dirs", nargs="+", help="run directories written by 'sonarslam run'")
    p.add_argument("--out", required=True, help="output directory (report.md and PNGs)")
    p.add_argument(
        "--rpe-delta",
        type=number(float, 0.0, 1e6, low_open=True),
        default=10.0,
        help="path length of evo's RPE (m, default 10)",
    )
    p.add_argument(
        "--align", action="store_true", help="Umeyama-align before evo's APE/RPE (default none)"
    )
    p.add_argument(
        "--no-source",
        action="store_true",
        help="do not re-open the runs' datasets (no reprojected map, no truth)",
    )
    add_quiet(p, progress=False)
    return p


def _sweep(sub: Subparsers) -> argparse.ArgumentParser:
    p = sub.add_parser(
        "sweep",
        help="Monte Carlo runs and parameter grids on Dask: ATE and ANEES per back end",
    )
    p.add_argument("--seeds", default="0-9", help="seeds: 0-49, 3, or 0,2,5-7 (default 0-9)")
    p.add_argument(
        "--world",
        default="drawn",
        choices=WORLDS,
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
    return p


#: Every command in ``--help`` order: its name, the function that adds its parser, and the
#: module whose ``command(args) -> int`` runs it (imported only then).
COMMANDS: tuple[tuple[str, Callable[[Subparsers], argparse.ArgumentParser], str], ...] = (
    ("simulate", _simulate, "sonarslam.slam.cli.simulate"),
    ("run", _run, "sonarslam.slam.cli.run"),
    ("plot-scans", _plot_scans, "sonarslam.slam.cli.plot_scans"),
    ("extract", _extract, "sonarslam.slam.cli.extract"),
    ("demo", _demo, "sonarslam.slam.cli.demo"),
    ("calibrate", _calibrate, "sonarslam.slam.cli.calibrate"),
    ("info", _info, "sonarslam.slam.cli.info"),
    ("report", _report, "sonarslam.slam.cli.report"),
    ("sweep", _sweep, "sonarslam.slam.cli.sweep"),
)
