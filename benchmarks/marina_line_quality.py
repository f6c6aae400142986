"""Line quality on the real marina against wall references fitted through the GPS-projected
leading edges of all scans (GPS + AHRS as a ruler only: it measures, it is an input to nothing).

python benchmarks/marina_line_quality.py --lines extract-gps extract-dr out/ekf \\
    --out out/marina_line_quality.json

1. **References** (:func:`sonarslam.slam.eval.walls.wall_references`): the nearest bin of each run of
   returns of every beam, projected with GPS positions and the AHRS heading
   (:func:`sonarslam.slam.run.sources.gps_ahrs_trajectory`), and the straight walls through them (seeded
   RANSAC, a robust refit, bends cut, sides kept). The picture (``--picture``, default beside
   ``--out``) draws them over the projected bins; ``--references FILE`` reuses saved ones.
2. **Lines**, any number of sets: ``extract-gps`` and ``extract-dr`` run the extractor
   (:func:`sonarslam.slam.run.extraction.extract`, the beams' preset unless ``--preset``) with GPS or
   dead-reckoning poses; a directory (``sonarslam run ... --out DIR`` or ``sonarslam extract``)
   or a ``lines.jsonl`` gives lines written before (a closed loop's own observations).
3. **Statistics** (:func:`sonarslam.slam.eval.line_quality.evaluate_lines`) per reference wall and over
   all: bias and scatter of the error in rho (m) and theta (deg) in each line's frame R, the
   NEES with the line's covariance (median, quantiles, mean) and the share beyond the 99 %
   chi2(2) gate; in three frames: the lines' own (``own``: R as the pose source that extracted
   them put it; for a closed loop its estimate), R re-projected onto the GPS pose at each
   line's time (``gps``: what the sonar saw, against where the wall is; the same as ``own`` for
   ``extract-gps``), and ``gps`` against the wall as the line's own scan's leading edges show
   it (``gps-scan``: without the ruler's error that lasts a scan, and without whatever a line
   shares with its scan's edges). Each line is paired with a wall once, as placed by the GPS,
   geometrically and without its covariance; the gates and the unmatched lines are in the
   output. The table prints, per wall and for all: bias, median, standard deviation and robust
   (1.4826 MAD) scatter of the rho error and the claimed sigma; the same for theta; the NEES
   quartiles, mean and the share beyond the gate.

Without the marina under ``$SONARSLAM_DATA`` the script says so and stops (``--source`` names
another dataset directory with GPS).
"""

from __future__ import annotations

import common  # noqa: F401  # first: one BLAS thread  # isort: skip

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np
from matplotlib.figure import Figure

from sonarslam.datasets.errors import DataError
from sonarslam.datasets.source import Dataset, open_dataset
from sonarslam.features.line import LineFeature
from sonarslam.slam.eval.leading_edges import EdgeConfig, Edges
from sonarslam.slam.eval.line_quality import AssociationGates, ScanReference, evaluate_lines
from sonarslam.slam.eval.line_stats import GATE_PROBABILITY
from sonarslam.slam.eval.walls import (
    WallFitConfig,
    WallReference,
    ruler_edges,
    ruler_wander,
    wall_references,
)
from sonarslam.slam.io.lines import read_lines_jsonl
from sonarslam.slam.io.trajectory import Trajectory
from sonarslam.slam.run.extraction import extract
from sonarslam.slam.run.sources import gps_ahrs_trajectory

RULER_NOTE = (
    "GPS positions with the AHRS heading are used only as a ruler: they place the leading edges "
    "the wall references are fitted through (and those of each line's scan, 'gps-scan'), and "
    "the pose of each line's frame R in the 'gps' and 'gps-scan' frames. They are an input to "
    "no estimator, extractor setting or calibration."
)


def finite(x: Any) -> Any:
    """``x`` with every NaN or infinite float as None (strict JSON)."""
    if isinstance(x, dict):
        return {k: finite(v) for k, v in x.items()}
    if isinstance(x, list):
        return [finite(v) for v in x]
    if isinstance(x, float) and not np.isfinite(x):
        return None
    return x


def scan_duration_s(ds: Dataset) -> float:
    """One 360 deg scan (s): the beams per turn times the median time between beams (the
    marina: 200 beams at ~14.7 Hz, ~13.6 s); the window of :func:`ruler_wander` and of
    :func:`sonarslam.slam.eval.line_quality.scan_lines` (the voters of a line are at most one turn old)."""
    t = np.array([b.t for b in ds.nav_beams()])
    return float(2.0 * np.pi / ds.config.sonar.step_rad * np.median(np.diff(t)))


def references(
    ds: Dataset, ruler: Trajectory, path: str | None
) -> tuple[list[WallReference], Edges, dict[str, Any]]:
    """Fitted walls (or those saved in ``path``), the edges, and their JSON block."""
    t0 = time.perf_counter()
    if path is None:
        walls, edges = wall_references(ds, ruler, EdgeConfig(), WallFitConfig())
    else:
        saved = json.loads(Path(path).read_text())["references"]["walls"]
        walls, edges = [WallReference.from_json(w) for w in saved], ruler_edges(ds, ruler)
    wander = ruler_wander(edges, walls, scan_duration_s(ds))
    block = {
        "edge_config": EdgeConfig().to_dict(),
        "fit_config": WallFitConfig().to_dict(),
        "loaded_from": path,
        "n_edges": int(edges.t_s.size),
        "seconds": time.perf_counter() - t0,
        "walls": [
            {**w.to_json(), "ruler_wander_m": float(v)} for w, v in zip(walls, wander, strict=True)
        ],
    }
    return walls, edges, block


def line_set(
    ds: Dataset, spec: str, preset: str | None, work: Path
) -> tuple[list[LineFeature], str]:
    """The lines of one ``--lines`` item and a description of where they come from."""
    if spec in ("extract-gps", "extract-dr"):
        poses = spec.split("-")[1]
        res = extract(ds, poses, work / spec, preset=preset, progress=False)
        return res.lines, f"extracted with {poses} poses, preset {res.stats['preset']}"
    p = Path(spec)
    path = p / "lines.jsonl" if p.is_dir() else p
    lines, _ = read_lines_jsonl(path)
    return lines, f"read from {path}"


def print_table(label: str, frame: str, report: dict[str, Any]) -> None:
    """One set of lines in one frame: a row per wall with lines, and all of them."""
    o = report["overall"]
    print(
        f"\n{label} [{frame}]: {o['n_matched']} of {o['n_lines']} lines matched "
        f"(unmatched {o['unmatched'] or 0}; at half / double gates {o['matched_at_half_gates']}"
        f" / {o['matched_at_double_gates']})"
    )
    print(
        "wall    n | rho (m): bias   med    sd  rsd claim | theta (deg): bias    sd   rsd claim"
        " | NEES q25   med   q75   mean out99"
    )
    rows = [r for r in report["walls"] if r["n"] > 0] + [{"wall": "all", **o}]
    for r in rows:
        print(
            f"{r['wall']!s:>4} {r['n']:4d} |     {r['rho_bias_m']:+6.2f} {r['rho_median_m']:+5.2f}"
            f" {r['rho_sd_m']:5.2f} {r['rho_robust_sd_m']:4.2f} {r['claimed_sigma_rho_m']:5.2f} |"
            f"       {r['theta_bias_deg']:+6.2f} {r['theta_sd_deg']:5.2f} {r['theta_robust_sd_deg']:5.2f}"
            f" {r['claimed_sigma_theta_deg']:5.2f} |    {r['nees_q25']:5.2f} {r['nees_median']:5.2f}"
            f" {r['nees_q75']:5.1f} {r['nees_mean']:6.1f} {100 * r['outside_gate']:4.1f}%"
        )
    print(
        f"per-wall scatter (pooled within walls): rho {o['per_wall_scatter_rho_m']:.2f} m, "
        f"theta {o['per_wall_scatter_theta_deg']:.2f} deg"
    )


def picture(
    path: Path, ds: Dataset, ruler: Trajectory, edges: Edges, walls: list[WallReference]
) -> None:
    """The references over the projected leading edges and the GPS track."""
    fig = Figure(figsize=(11, 14), dpi=110)
    ax = fig.subplots()
    ax.plot(
        edges.points_w[:, 0],
        edges.points_w[:, 1],
        ",",
        color="0.45",
        label="leading edges (GPS + AHRS)",
    )
    xy = ruler.poses(ruler.t_s)[:, :2]
    ax.plot(xy[:, 0], xy[:, 1], "-", lw=0.5, color="tab:blue", label="GPS track")
    for w in walls:
        e = w.endpoints_w
        ax.plot(e[:, 0], e[:, 1], "-", lw=2.0, color="tab:red")
        mid = e.mean(axis=0)
        normal = np.array([np.cos(w.line_w[1]), np.sin(w.line_w[1])]) * w.side
        ax.annotate(
            "",
            mid + 3.0 * normal,
            mid,
            arrowprops={"arrowstyle": "->", "color": "tab:red", "lw": 0.6},
        )
        ax.text(
            *(mid + 5.0 * normal),
            str(w.index),
            fontsize=7,
            color="darkred",
            ha="center",
            va="center",
        )
    ax.plot([], [], "-", color="tab:red", label="wall references (arrow: water side)")
    ax.set_aspect("equal")
    ax.set_xlabel("East (m)")
    ax.set_ylabel("North (m)")
    ax.grid(True, lw=0.3)
    ax.legend(loc="upper right", fontsize="small")
    ax.set_title(
        f"{ds.name}: {len(walls)} wall references through {edges.t_s.size} leading edges; GPS as a ruler only"
    )
    fig.tight_layout()
    fig.savefig(path)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--source", default="marina", help="dataset (default: the marina)")
    parser.add_argument(
        "--lines",
        nargs="+",
        default=["extract-gps", "extract-dr"],
        help="extract-gps | extract-dr | a run or extraction directory | a lines.jsonl (several allowed)",
    )
    parser.add_argument(
        "--preset", default=None, help="extractor preset for extract-* (default: the beams')"
    )
    parser.add_argument(
        "--gates",
        nargs=2,
        type=float,
        default=None,
        metavar=("METRES", "DEGREES"),
        help="association gates: largest mean end distance and angle to the wall (default 5 m, 30 deg)",
    )
    parser.add_argument("--out", default="out/marina_line_quality.json", help="results JSON")
    parser.add_argument("--picture", default=None, help="references PNG (default: beside --out)")
    parser.add_argument(
        "--references", default=None, help="reuse the walls of an earlier results JSON"
    )
    parser.add_argument(
        "--work",
        default=None,
        help="where extract-* write their lines (default: a temporary folder)",
    )
    args = parser.parse_args()
    try:
        ds = open_dataset(args.source)
    except DataError as exc:
        print(f"skipped: {exc}")  # a measurement of real data; nothing to fake
        return 0
    t_start = time.perf_counter()
    ruler = gps_ahrs_trajectory(ds)
    walls, edges, ref_block = references(ds, ruler, args.references)
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    pic = Path(args.picture) if args.picture else out.with_suffix(".png")
    picture(pic, ds, ruler, edges, walls)
    print(RULER_NOTE)
    print(
        f"{len(walls)} wall references through {edges.t_s.size} leading edges ({ref_block['seconds']:.1f} s); picture: {pic}"
    )
    gates = AssociationGates()
    if args.gates is not None:
        gates = AssociationGates(
            max_distance_m=args.gates[0], max_angle_rad=np.deg2rad(args.gates[1])
        )
    bTs = ds.config.sonar_mounting.as_pose()
    scan_s = scan_duration_s(ds)
    work = Path(args.work) if args.work else Path(tempfile.mkdtemp(prefix="line_quality_"))
    sets: dict[str, Any] = {}
    for spec in args.lines:
        t0 = time.perf_counter()
        lines, origin = line_set(ds, spec, args.preset, work)
        same = spec == "extract-gps"
        reports = evaluate_lines(lines, walls, ruler, bTs, gates, (edges, ScanReference(scan_s)))
        frames = {"own": reports["own"], "gps": reports["ruler"], "gps-scan": reports["ruler_scan"]}
        sets[spec] = {"origin": origin, "seconds": time.perf_counter() - t0, **frames}
        for frame, rep in frames.items():
            if frame != "own" or not same:  # extract-gps: own is gps
                print_table(f"{spec} ({origin})", frame, rep)
    result = {
        "dataset": str(ds.root),
        "ruler": RULER_NOTE,
        "sign": "e = line - wall in the line's frame R; e_rho > 0: the line lies beyond the wall's face seen from the sonar",
        "nees_gate": f"chi2(2) at {GATE_PROBABILITY}",
        "gates": gates.to_dict(),
        "references": ref_block,
        "sets": sets,
        "seconds": time.perf_counter() - t_start,
    }
    out.write_text(json.dumps(finite(result), indent=1, allow_nan=False) + "\n")
    print(f"\nresults: {out} ({result['seconds']:.0f} s)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
