"""Two or more settings of a back end on drawn worlds, against the truth: which default.

python benchmarks/drawn_defaults.py --seeds 0-9 [--cache out/sim-drawn] [--workers 2] \\
    [--backend isam2|ekf] --variant NAME=SCOPE.FIELD=V,SCOPE.FIELD=V ... [--out DIR]

Each seed's drawn world is simulated and calibrated GPS-free once into ``--cache`` (as
``sonarslam sweep --calibrate`` does: :func:`sonarslam.slam.run.sweep.simulate_cached`,
:func:`~sonarslam.slam.run.sweep.calibrate_cached`), then run (``sonarslam run WORLD --config
calibration.toml``, a process each, ``--workers`` at a time) with dead reckoning and with
``--backend`` (the factor graph by default) under each ``--variant`` (``NAME=`` alone: the
defaults). Per variant, for the online and (a smoother's) the smoothed estimates over the seeds: the mean ATE against the truth, unaligned and
SE(2)-aligned; the share of worlds where it beats dead reckoning and the count worse than it by
more than 10 %; the pose ANEES (the mean over the runs of each run's mean NEES against the
truth, :func:`sonarslam.slam.eval.consistency.nees_series`) and the runs above 10; and where the
run estimates them, the share of worlds whose sonar mounting (x, y, yaw) and range scale lie
within 2 sigma of the truth (:func:`sonarslam.slam.eval.truth.true_calibration`). The truth is
a ruler only. Writes ``DIR/runs/<variant or dr>/<seed>/`` and ``DIR/result.json``; prints the
table.
"""

from __future__ import annotations

import common  # noqa: F401  # first: one BLAS thread  # isort: skip

import argparse
import json
import math
import os
import subprocess
import sys
import warnings
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import Any

import numpy as np

from sonarslam.datasets.errors import DataWarning
from sonarslam.slam.eval.consistency import nees_series
from sonarslam.slam.eval.truth import calibration_sigmas, true_calibration
from sonarslam.slam.run.report_data import load_run
from sonarslam.slam.run.sweep import calibrate_cached, parse_seeds, simulate_cached

#: The estimates scored: label -> the metrics.json infix of its ATE keys.
ESTIMATES = {"online": "", "smoothed": "_smoothed"}
#: The calibration estimates scored against the truth (``metrics.json`` keys).
CALIBRATION = (
    "state_sonar_x_m",
    "state_sonar_y_m",
    "state_sonar_yaw_deg",
    "state_sonar_range_scale",
)


def run_one(world: str, calibration: str, args: list[str], out: Path) -> dict[str, Any]:
    """``sonarslam run`` of one world (kept when its metrics.json exists); its metrics."""
    if not (out / "metrics.json").is_file():
        out.mkdir(parents=True, exist_ok=True)
        code = "import sys; from sonarslam.slam.cli.main import main; sys.exit(main(sys.argv[1:]))"
        cmd = [sys.executable, "-c", code, "run", world, "--config", calibration]
        cmd += ["--out", str(out), "--quiet", *args]
        env = {**os.environ, "OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1"}
        done = subprocess.run(cmd, env={**env, "MPLBACKEND": "Agg"}, capture_output=True, text=True)
        if done.returncode != 0:
            raise RuntimeError(f"{' '.join(cmd)}: {done.stderr.strip()[-300:]}")
    return dict(json.loads((out / "metrics.json").read_text()))


def score(runs: dict[int, dict[str, Any]], dr: dict[int, dict[str, Any]], dirs: dict[int, Path]):
    """The figures of one variant over its seeds (module docstring)."""
    seeds = sorted(runs)
    out: dict[str, Any] = {"worlds": len(seeds)}
    dr_u = np.array([dr[s]["ate_truth_mean_m"] for s in seeds])
    dr_a = np.array([dr[s]["ate_truth_aligned_mean_m"] for s in seeds])
    for label, infix in ESTIMATES.items():
        if f"ate_truth{infix}_mean_m" not in runs[seeds[0]]:
            continue  # a filter has no smoothed estimate
        u = np.array([runs[s][f"ate_truth{infix}_mean_m"] for s in seeds])
        a = np.array([runs[s][f"ate_truth_aligned{infix}_mean_m"] for s in seeds])
        out[label] = {
            "ate_mean_m": float(u.mean()),
            "ate_aligned_mean_m": float(a.mean()),
            "beats_dr": float(np.mean(u < dr_u)),
            "beats_dr_aligned": float(np.mean(a < dr_a)),
            "worse_10pct": int(np.sum(u > 1.1 * dr_u)),
            "worse_10pct_aligned": int(np.sum(a > 1.1 * dr_a)),
            "per_seed": {s: [float(x), float(y)] for s, x, y in zip(seeds, u, a, strict=True)},
        }
    nees = []
    within: dict[str, list[bool]] = {k: [] for k in CALIBRATION}
    for s in seeds:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", DataWarning)
            run = load_run(dirs[s])
        assert run.truth is not None and run.dataset is not None
        nees.append(nees_series(run.trajectory, run.truth).mean)
        truth = true_calibration(run.dataset, run.trajectory.span_s[1])
        for key in CALIBRATION:
            if key in runs[s]:
                within[key].append(abs(calibration_sigmas(runs[s], truth, key)) <= 2.0)
    out["anees"] = float(np.mean(nees))
    out["nees_median"] = float(np.median(nees))
    out["nees_above_10"] = int(np.sum(np.array(nees) > 10.0))
    out["within_2sigma"] = {k: float(np.mean(v)) for k, v in within.items() if v}
    return out


def table(result: dict[str, Any]) -> str:
    rows = [
        "| variant | estimate | ATE mean / aligned (m) | beats DR / aligned | worse by > 10 %"
        " / aligned | ANEES (median; runs > 10) | within 2σ: x, y, yaw, range scale |",
        "|---|---|---|---|---|---|---|",
    ]
    for name, v in result["variants"].items():
        w = v["within_2sigma"]
        cal = ", ".join(f"{100 * w[k]:.0f} %" for k in CALIBRATION if k in w) or "-"
        for label in (e for e in ESTIMATES if e in v):
            e = v[label]
            nees = (
                f"{v['anees']:.2f} ({v['nees_median']:.2f}; {v['nees_above_10']})"
                if label == "online"
                else ""
            )
            rows.append(
                f"| {name} | {label} | {e['ate_mean_m']:.2f} / {e['ate_aligned_mean_m']:.2f} | "
                f"{100 * e['beats_dr']:.0f} % / {100 * e['beats_dr_aligned']:.0f} % | "
                f"{e['worse_10pct']} / {e['worse_10pct_aligned']} | {nees} | "
                f"{cal if label == 'online' else ''} |"
            )
    dr = result["dr_mean_m"]
    return f"dead reckoning: {dr[0]:.2f} / aligned {dr[1]:.2f} m\n\n" + "\n".join(rows) + "\n"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    ap.add_argument("--seeds", required=True, help='drawn seeds, e.g. "0-9" or "0,3,20000-20007"')
    ap.add_argument("--cache", default="out/sim-drawn", help="simulated worlds, reused")
    ap.add_argument("--variant", action="append", required=True, metavar="NAME=[SCOPE.FIELD=V,...]")
    ap.add_argument("--workers", type=int, default=1)
    ap.add_argument("--backend", default="isam2", choices=["isam2", "ekf"])
    ap.add_argument("--out", type=Path, default=Path("out/drawn_defaults"))
    args = ap.parse_args(argv)
    variants: dict[str, list[str]] = {}
    for v in args.variant:
        name, _, sets = v.partition("=")
        variants[name] = [a for s in sets.split(",") if s for a in ("--set", s)]
    seeds = parse_seeds(args.seeds)
    worlds = {}
    for s in seeds:
        folder = simulate_cached("drawn", s, None, args.cache)
        worlds[s] = (folder, calibrate_cached(folder))
    jobs = []  # seed by seed: a partial run has whole worlds
    for s in seeds:
        jobs.append(("dr", s, ["--backend", "dr"]))
        jobs += [(n, s, ["--backend", args.backend, *a]) for n, a in variants.items()]

    def work(job: tuple[str, int, list[str]]) -> dict[str, Any]:
        name, seed, a = job
        return run_one(*worlds[seed], a, args.out / "runs" / name / str(seed))

    with ThreadPoolExecutor(max_workers=args.workers) as pool:
        metrics = list(pool.map(work, jobs))
    by: dict[str, dict[int, dict[str, Any]]] = {}
    for (name, seed, _), m in zip(jobs, metrics, strict=True):
        by.setdefault(name, {})[seed] = m
    dr = by.pop("dr")
    result = {
        "seeds": seeds,
        "backend": args.backend,
        "variants_settings": variants,
        "dr_mean_m": [
            float(np.mean([m["ate_truth_mean_m"] for m in dr.values()])),
            float(np.mean([m["ate_truth_aligned_mean_m"] for m in dr.values()])),
        ],
        "variants": {
            n: score(r, dr, {s: args.out / "runs" / n / str(s) for s in r}) for n, r in by.items()
        },
        "load_average": list(os.getloadavg()),
    }
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "result.json").write_text(json.dumps(result, indent=1) + "\n")
    print(table(result))
    return 0 if all(math.isfinite(v["anees"]) for v in result["variants"].values()) else 1


if __name__ == "__main__":
    raise SystemExit(main())
