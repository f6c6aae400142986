"""Speed of the line extractor on one core.

1. The whole marina (GPS + AHRS poses, an extractor preset of :mod:`sonarslam.slam.run.presets`,
   ``marina-fit`` by default): real-time factor (data span / wall
   time of the loop over the beams; required >= 200x) and the time per beam (one
   ``LineExtractor.add``: segmentation, storage, and the vote when due), p50 and p99.
2. Voting one stored full sector, side by side in the same run: ours
   (``LineExtractor.cast_votes`` + ``find_winners`` on a snapshot: the sonar-model arc votes of
   eqs. 2-4 and the winners with their voters removed) against scikit-image's
   ``skimage.transform.hough_line`` on the same bins (their beam-axis points in R) rasterised into
   an image of ``--pixel`` m pixels over the sector's bounding box, with the same theta
   resolution (``n_theta / 2`` angles over ``[-pi/2, pi/2)``, skimage's signed-rho convention,
   which is our ``[-pi, pi)`` with ``rho >= 0``). Both are timed with ``time.perf_counter`` over
   ``--repeats`` runs (median reported); the rasterisation is timed apart. The two are not the
   same computation: ours votes each bin over the ``alpha + 2 beta`` fan of normals of the sonar
   model only, skimage votes each pixel over all angles, and ``hough_line`` finds no winners
   (``hough_line_peaks`` is timed too).

Without ``$SONARSLAM_DATA/marina`` a simulated harbour (600 s, raw beams, truth poses, the
extractor's defaults) replaces it, and the output says so. The process is pinned to one CPU and
the BLAS thread pools to one thread before numpy loads.

Usage::

    .venv/bin/python benchmarks/extractor_speed.py --out out/extractor_speed.json
"""

from __future__ import annotations

from common import pin_one_core  # first: one BLAS thread  # isort: skip

import argparse
import json
import sys
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from sonarslam.datasets.simulator import make_scenario, simulate_records
from sonarslam.datasets.source import data_root, open_dataset
from sonarslam.features.config import ExtractorConfig
from sonarslam.features.extractor import LineExtractor
from sonarslam.features.hough import find_winners
from sonarslam.features.pose_source import PoseSource
from sonarslam.features.sector import SectorSnapshot
from sonarslam.slam.run.extraction import extract_lines
from sonarslam.slam.run.presets import EXTRACTOR_PRESETS
from sonarslam.slam.run.sources import gps_ahrs_trajectory
from sonarslam.sonar.beam import Mounting, SonarBeam, SonarHead

REALTIME_FACTOR_MIN = 200.0


def load_run(
    source: str, preset: str
) -> tuple[str, list[SonarBeam], SonarHead, Mounting, PoseSource, ExtractorConfig]:
    """The marina with GPS poses and an extractor preset, or a simulated harbour when it is
    absent."""
    root = data_root()
    if source == "marina" and root is not None and (root / "marina").is_dir():
        ds = open_dataset("marina")
        poses = gps_ahrs_trajectory(ds)
        t0, t1 = poses.span_s
        beams = [b for b in ds.nav_beams() if t0 <= b.t <= t1]
        cfg = EXTRACTOR_PRESETS[preset]
        label = f"marina (GPS + AHRS poses, the {preset} preset)"
        return label, beams, ds.config.sonar, ds.config.sonar_mounting, poses, cfg
    sim = simulate_records(make_scenario("harbour", 1))
    sc = sim.scenario
    label = "simulated harbour seed 1, 600 s (truth poses, default ExtractorConfig)"
    if source == "marina":
        label += ": the marina was not found under $SONARSLAM_DATA"
    return label, sim.beams, sc.head, sc.sonar_mounting, sim.trajectory, ExtractorConfig()


def time_repeats(fn: Callable[[], Any], repeats: int) -> np.ndarray:
    """Wall times of ``repeats`` calls (s), after one warm-up call."""
    fn()
    out = np.empty(repeats)
    for k in range(repeats):
        a = time.perf_counter()
        fn()
        out[k] = time.perf_counter() - a
    return out


def full_sector(
    beams: list[SonarBeam],
    head: SonarHead,
    mounting: Mounting,
    poses: PoseSource,
    config: ExtractorConfig,
    end_fraction: float,
) -> tuple[LineExtractor, SectorSnapshot]:
    """A full sector stored from the beams ending at ``end_fraction`` of the run, no vote made."""
    ex = LineExtractor(config.replace(vote_every_n_beams=10**9), head, mounting, poses)
    end = max(int(end_fraction * len(beams)), ex.sector.capacity)
    for b in beams[end - ex.sector.capacity : end]:
        ex.add(b)
    assert ex.sector.is_full and ex.n_votes == 0
    return ex, ex.sector.snapshot()


def rasterise(points_m: np.ndarray, pixel_m: float) -> np.ndarray:
    """Binary image of points over their bounding box (one pixel row per ``pixel_m`` in y)."""
    lo = points_m.min(axis=0)
    ij = np.floor((points_m - lo) / pixel_m).astype(np.int64)
    img = np.zeros((int(ij[:, 1].max()) + 1, int(ij[:, 0].max()) + 1), dtype=bool)
    img[ij[:, 1], ij[:, 0]] = True
    return img


def voting_comparison(
    ex: LineExtractor, snap: SectorSnapshot, pixel_m: float, repeats: int
) -> dict[str, Any]:
    """Ours against skimage on one snapshot (module docstring); times in ms (median)."""
    from skimage.transform import hough_line, hough_line_peaks

    cfg, grid, fin = ex.config, ex.grid, snap.final

    def ours() -> int:
        votes = ex.cast_votes(fin)
        winners, _ = find_winners(
            votes,
            grid,
            cfg.min_votes,
            max_winners=cfg.max_lines_per_vote,
            suppress_theta_cells=cfg.suppress_theta_cells,
            suppress_rho_cells=cfg.suppress_rho_cells,
        )
        return len(winners)

    points = fin.points_m()
    n_angles = grid.n_theta // 2
    angles = np.linspace(-np.pi / 2, np.pi / 2, n_angles, endpoint=False)
    image = rasterise(points, pixel_m)

    def sk_vote() -> np.ndarray:
        return hough_line(image, theta=angles)[0]

    def sk_peaks() -> int:
        h, th, d = hough_line(image, theta=angles)
        return len(hough_line_peaks(h, th, d, threshold=cfg.min_votes)[0])

    return {
        "t_s": snap.t_ref_s,
        "bins": len(fin),
        "image_shape": list(image.shape),
        "winners_ours": ours(),
        "peaks_skimage": sk_peaks(),
        "ours_ms": float(np.median(time_repeats(ours, repeats)) * 1e3),
        "rasterise_ms": float(
            np.median(time_repeats(lambda: rasterise(points, pixel_m), repeats)) * 1e3
        ),
        "skimage_hough_line_ms": float(np.median(time_repeats(sk_vote, repeats)) * 1e3),
        "skimage_with_peaks_ms": float(np.median(time_repeats(sk_peaks, repeats)) * 1e3),
    }


def voting_over_sectors(
    beams: list[SonarBeam],
    head: SonarHead,
    mounting: Mounting,
    poses: PoseSource,
    config: ExtractorConfig,
    n_sectors: int,
    pixel_m: float,
    repeats: int,
) -> dict[str, Any]:
    """:func:`voting_comparison` on ``n_sectors`` full sectors spread evenly over the run."""
    per = []
    ex = None
    for frac in np.linspace(0.05, 0.95, n_sectors):
        ex, snap = full_sector(beams, head, mounting, poses, config, float(frac))
        per.append(voting_comparison(ex, snap, pixel_m, repeats))
    assert ex is not None
    tot = {k: float(sum(p[k] for p in per)) for k in ("ours_ms", "skimage_hough_line_ms", "skimage_with_peaks_ms", "rasterise_ms")}  # fmt: skip
    big = max(per, key=lambda p: p["bins"])
    return {
        "sectors": n_sectors,
        "beams_per_sector": ex.sector.capacity,
        "grid_n_theta": ex.grid.n_theta,
        "grid_n_rho": ex.grid.n_rho,
        "theta_res_deg": float(np.rad2deg(ex.grid.theta_res_rad)),
        "rho_res_m": ex.grid.rho_res_m,
        "skimage_angles": ex.grid.n_theta // 2,
        "pixel_m": pixel_m,
        "min_votes": config.min_votes,
        "repeats": repeats,
        "bins_median": float(np.median([p["bins"] for p in per])),
        "total_ms": tot,
        "ratio_skimage_hough_line_over_ours": tot["skimage_hough_line_ms"] / tot["ours_ms"],
        "ratio_skimage_with_peaks_over_ours": tot["skimage_with_peaks_ms"] / tot["ours_ms"],
        "largest_sector": big,
        "ratio_largest_skimage_hough_line_over_ours": big["skimage_hough_line_ms"] / big["ours_ms"],
        "per_sector": per,
    }


def run(
    source: str, pixel_m: float, repeats: int, n_sectors: int, preset: str = "marina-fit"
) -> dict[str, Any]:
    """Both measurements (the JSON written by :func:`main`)."""
    cpu = pin_one_core()
    label, beams, head, mounting, poses, cfg = load_run(source, preset)
    ex = LineExtractor(cfg, head, mounting, poses)
    lines, dt, wall_s = extract_lines(beams, ex)
    data_s = float(beams[-1].t - beams[0].t)
    return {
        "run": label,
        "cpu": cpu,
        "beams": len(beams),
        "features": len(lines),
        "votes": ex.n_votes,
        "data_s": data_s,
        "wall_s": wall_s,
        "realtime_factor": data_s / wall_s,
        "realtime_factor_ok": data_s / wall_s >= REALTIME_FACTOR_MIN,
        "beam_time_p50_us": float(np.percentile(dt, 50) * 1e6),
        "beam_time_p99_us": float(np.percentile(dt, 99) * 1e6),
        "beam_time_max_us": float(dt.max() * 1e6),
        "voting": voting_over_sectors(
            beams, head, mounting, poses, cfg, n_sectors, pixel_m, repeats
        ),
    }


def format_report(res: dict[str, Any]) -> str:
    v = res["voting"]
    t, big = v["total_ms"], v["largest_sector"]
    return "\n".join(
        [
            f"{res['run']}, one core (cpu {res['cpu']})",
            f"  {res['beams']} beams, {res['features']} lines, {res['votes']} votes: "
            f"{res['data_s']:.0f} s of data in {res['wall_s']:.2f} s = "
            f"{res['realtime_factor']:.0f}x real time (required >= {REALTIME_FACTOR_MIN:.0f}x)",
            f"  per beam: p50 {res['beam_time_p50_us']:.0f} us, p99 {res['beam_time_p99_us']:.0f} us,"
            f" max {res['beam_time_max_us']:.0f} us",
            f"voting {v['sectors']} full sectors of {v['beams_per_sector']} beams spread over the run"
            f" (median {v['bins_median']:.0f} bins); grid {v['grid_n_theta']} x {v['grid_n_rho']}"
            f" ({v['theta_res_deg']:.2f} deg x {v['rho_res_m']} m); skimage {v['skimage_angles']}"
            f" angles on {v['pixel_m']} m pixels; median of {v['repeats']} per sector, summed:",
            f"  ours (cast_votes + find_winners):       {t['ours_ms']:8.2f} ms",
            f"  skimage hough_line:                     {t['skimage_hough_line_ms']:8.2f} ms"
            f"  (rasterising: {t['rasterise_ms']:.2f} ms more)",
            f"  skimage hough_line + hough_line_peaks:  {t['skimage_with_peaks_ms']:8.2f} ms",
            f"  ratio skimage / ours: {v['ratio_skimage_hough_line_over_ours']:.2f} (hough_line), "
            f"{v['ratio_skimage_with_peaks_over_ours']:.2f} (with peaks)",
            f"  largest sector ({big['bins']} bins, image {big['image_shape'][0]} x "
            f"{big['image_shape'][1]}): ours {big['ours_ms']:.2f} ms ({big['winners_ours']} winners),"
            f" hough_line {big['skimage_hough_line_ms']:.2f} ms, with peaks "
            f"{big['skimage_with_peaks_ms']:.2f} ms ({big['peaks_skimage']} peaks >= "
            f"{v['min_votes']} votes)",
        ]
    )


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--source", default="marina", help="'marina' (default) or 'sim'")
    p.add_argument("--pixel", type=float, default=0.1, help="skimage pixel size (m, default 0.1)")
    p.add_argument("--repeats", type=int, default=50, help="timed repeats (default 50)")
    p.add_argument(
        "--sectors", type=int, default=20, help="full sectors compared, spread over the run (20)"
    )
    p.add_argument(
        "--preset",
        default="marina-fit",
        choices=sorted(EXTRACTOR_PRESETS),
        help="extractor preset on the marina (default marina-fit: the least-squares lines over a"
        " 180 deg sector; 'marina' is the closed loops')",
    )
    p.add_argument("--out", default="out/extractor_speed.json", help="results JSON")
    return p


def main(argv: Sequence[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    res = run(args.source, args.pixel, args.repeats, args.sectors, args.preset)
    print(format_report(res))
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(res, indent=2) + "\n")
    print(f"results: {out.resolve()}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
