"""The offline estimate on drawn worlds, against the truth: its settings compared, and the
held-back worlds' verdict (issue 40's targets).

python benchmarks/offline_drawn.py --seeds 0-9 [--noise own,marina] [--cache out/sim-drawn] \\
    [--variant NAME=FIELD=V,FIELD=V ...] [--set SCOPE.FIELD=V ...] [--workers 2] [--out out/offline_drawn]

Each seed's drawn world is simulated and calibrated GPS-free once into ``--cache`` (as
``benchmarks/drawn_defaults.py`` does), then run once per noise model with dead reckoning and
with the factor graph, its offline estimate off (``sonarslam run WORLD --backend isam2 --config
C --set isam2.offline=false``; C the world's GPS-free calibration, with the marina's noise model
``benchmarks/marina_noise_model.toml`` over it for ``--noise marina``: the estimators told a
constant AHRS bias and no DVL scale error, as on the marina). Each ``--variant`` (fields of
:class:`sonarslam.slam.backends.isam2.config.OfflineConfig`; ``NAME=`` alone: its defaults) is
then made from the saved run (:func:`sonarslam.slam.run.offline.offline_from_saved`), so the
variants share one online run. Scored against the truth (a ruler only): the mean ATE over the
worlds, unaligned and SE(2)-aligned, of the online, smoothed and offline estimates; the share of
worlds where the offline estimate beats dead reckoning and the smoothed estimate; the count worse
than dead reckoning by more than 10 %; the offline estimate's pose ANEES against the truth (its
covariance's honesty: 3 when consistent) and CPU seconds.

Writes ``OUT/result.json`` (every world's figures), each world's runs and offline trajectories
(``OUT/worlds/NOISE/SEED/``), and prints the table.
"""

from __future__ import annotations

import common  # noqa: F401  # first: one BLAS thread  # isort: skip

import argparse
import json
import os
import time
import warnings
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from typing import Any

import numpy as np

from sonarslam.datasets.errors import DataWarning
from sonarslam.datasets.source import open_dataset
from sonarslam.settings import replace_checked
from sonarslam.slam.backends.isam2.config import OfflineConfig
from sonarslam.slam.eval.ate import ate_against_truth
from sonarslam.slam.eval.consistency import nees_series
from sonarslam.slam.eval.truth import truth_trajectory
from sonarslam.slam.io.trajectory import write_tum
from sonarslam.slam.run.offline import offline_from_saved
from sonarslam.slam.run.sweep import calibrate_cached, parse_seeds, simulate_cached

from drawn_defaults import run_one, with_noise_model  # isort: skip
from offline_variants import parse_variant  # one NAME=FIELD=V,... syntax  # isort: skip

HERE = Path(__file__).resolve().parent
NOISE_MODELS = {"own": None, "marina": HERE / "marina_noise_model.toml"}
#: The estimates of a run scored (metrics.json infixes) beside the offline one.
RUN_ESTIMATES = {"dr": "", "online": "", "smoothed": "_smoothed"}


def world_job(
    job: tuple[int, str, str, str, Path, dict[str, dict[str, Any]], tuple[str, ...]],
) -> dict[str, Any]:
    """One world and noise model: its runs (the iSAM2 run with the ``--set`` settings), then
    every variant of the offline estimate."""
    seed, noise_name, world, calibration, out, variants, settings = job
    config = with_noise_model(calibration, NOISE_MODELS[noise_name])
    dr = run_one(world, config, ["--backend", "dr"], out / "dr")
    graph_dir = out / "isam2"
    extra = [a for setting in settings for a in ("--set", setting)]
    online = run_one(
        world, config, ["--backend", "isam2", "--set", "isam2.offline=false", *extra], graph_dir
    )
    row: dict[str, Any] = {
        "seed": seed,
        "noise": noise_name,
        "dr": [dr["ate_truth_mean_m"], dr["ate_truth_aligned_mean_m"]],
        "online": [online["ate_truth_mean_m"], online["ate_truth_aligned_mean_m"]],
        "smoothed": [
            online["ate_truth_smoothed_mean_m"],
            online["ate_truth_aligned_smoothed_mean_m"],
        ],
        "variants": {},
    }
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DataWarning)
        dataset = open_dataset(world, config_override=config)
        truth = truth_trajectory(dataset)
        for name, fields in variants.items():
            cached = out / f"offline_{name}.json"
            if cached.is_file():
                row["variants"][name] = json.loads(cached.read_text())
                continue
            cfg = replace_checked(
                OfflineConfig(), fields, prefix="isam2.offline.", parse_strings=False
            )
            cpu0 = time.process_time()
            found = offline_from_saved(graph_dir, dataset, cfg)
            cpu = time.process_time() - cpu0
            u = ate_against_truth(found.trajectory, truth).ate_mean_m
            a = ate_against_truth(found.trajectory, truth, align=True).ate_mean_m
            nees = nees_series(found.trajectory, truth, "pose").mean
            v = {"ate": [u, a], "nees_pose": nees, "cpu_s": cpu, **found.metrics()}
            write_tum(out / f"offline_{name}.tum", found.trajectory)
            cached.write_text(json.dumps(v) + "\n")
            row["variants"][name] = v
    return row


def summary(rows: list[dict[str, Any]], name: str) -> dict[str, Any]:
    """One variant over the worlds of ``rows``."""

    def col(key: str, i: int) -> np.ndarray:
        return np.array([r[key][i] for r in rows])

    off = np.array([r["variants"][name]["ate"] for r in rows])
    out: dict[str, Any] = {"worlds": len(rows)}
    for i, view in enumerate(("unaligned", "aligned")):
        dr, sm = col("dr", i), col("smoothed", i)
        out[view] = {
            "offline_mean_m": float(off[:, i].mean()),
            "online_mean_m": float(col("online", i).mean()),
            "smoothed_mean_m": float(sm.mean()),
            "dr_mean_m": float(dr.mean()),
            "beats_dr": float(np.mean(off[:, i] < dr)),
            "beats_smoothed": float(np.mean(off[:, i] < sm)),
            "worse_than_dr_10pct": int(np.sum(off[:, i] > 1.1 * dr)),
        }
    out["cpu_s_mean"] = float(np.mean([r["variants"][name]["cpu_s"] for r in rows]))
    nees = [r["variants"][name].get("nees_pose", float("nan")) for r in rows]
    out["anees_pose"] = float(np.nanmean(nees)) if np.isfinite(nees).any() else float("nan")
    return out


def table(result: dict[str, Any]) -> str:
    lines = [
        "| noise | variant | worlds | offline / smoothed / online / DR, mean m (aligned) |"
        " offline beats DR (aligned) | beats smoothed (aligned) | worse than DR by > 10 % |"
        " offline ANEES (pose, 3 dof) | CPU s |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for noise, variants in result["summary"].items():
        for name, s in variants.items():
            u, a = s["unaligned"], s["aligned"]
            lines.append(
                f"| {noise} | {name} | {s['worlds']} | {u['offline_mean_m']:.2f} /"
                f" {u['smoothed_mean_m']:.2f} / {u['online_mean_m']:.2f} / {u['dr_mean_m']:.2f}"
                f" ({a['offline_mean_m']:.2f} / {a['smoothed_mean_m']:.2f} /"
                f" {a['online_mean_m']:.2f} / {a['dr_mean_m']:.2f}) |"
                f" {100 * u['beats_dr']:.0f} % ({100 * a['beats_dr']:.0f} %) |"
                f" {100 * u['beats_smoothed']:.0f} % ({100 * a['beats_smoothed']:.0f} %) |"
                f" {u['worse_than_dr_10pct']} ({a['worse_than_dr_10pct']}) |"
                f" {s['anees_pose']:.2f} | {s['cpu_s_mean']:.1f} |"
            )
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    ap.add_argument("--seeds", required=True, help='drawn seeds, e.g. "0-9" or "0,3,20000-20007"')
    ap.add_argument("--noise", default="own,marina", help="noise models: own, marina")
    ap.add_argument("--cache", default="out/sim-drawn", help="simulated worlds, reused")
    ap.add_argument("--variant", action="append", default=[], metavar="NAME=[FIELD=V,...]")
    ap.add_argument("--workers", type=int, default=1)
    ap.add_argument(
        "--set",
        action="append",
        default=[],
        metavar="SCOPE.FIELD=V",
        help="a setting of every world's iSAM2 run (repeatable; e.g. isam2.range_scale_sigma=0.04)",
    )
    ap.add_argument("--out", type=Path, default=Path("out/offline_drawn"))
    args = ap.parse_args(argv)
    variants: dict[str, dict[str, Any]] = {}
    for v in args.variant or ["default="]:
        try:
            name, fields = parse_variant(v)
        except ValueError as exc:
            ap.error(str(exc))
        variants[name] = fields
    noises = [n for n in args.noise.split(",") if n]
    unknown = [n for n in noises if n not in NOISE_MODELS]
    if unknown:
        ap.error(f"--noise: unknown {unknown}; the models are {sorted(NOISE_MODELS)}")
    seeds = parse_seeds(args.seeds)
    jobs = []
    for s in seeds:
        folder = simulate_cached("drawn", s, None, args.cache)
        calibration = calibrate_cached(folder)
        for noise in noises:
            out = args.out / "worlds" / noise / str(s)
            jobs.append((s, noise, folder, calibration, out, variants, tuple(args.set)))
    with ProcessPoolExecutor(max_workers=args.workers) as pool:
        rows = list(pool.map(world_job, jobs))
    result: dict[str, Any] = {
        "seeds": seeds,
        "variants": {k: {f: str(v) for f, v in fs.items()} for k, fs in variants.items()},
        "rows": rows,
        "summary": {
            noise: {
                name: summary([r for r in rows if r["noise"] == noise], name) for name in variants
            }
            for noise in noises
        },
        "load_average": list(os.getloadavg()),
    }
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "result.json").write_text(json.dumps(result, indent=1) + "\n")
    print(table(result))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
