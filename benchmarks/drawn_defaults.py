"""Two or more settings of a back end on drawn worlds, against the truth: which default.

python benchmarks/drawn_defaults.py --seeds 0-9 [--cache out/sim-drawn] [--workers 2] \\
    [--backend isam2|ekf] [--noise-model FILE] --variant NAME=SCOPE.FIELD=V,SCOPE.FIELD=V ... \\
    [--out DIR]

Each seed's drawn world is simulated and calibrated GPS-free once into ``--cache`` (as
``sonarslam sweep --calibrate`` does: :func:`sonarslam.slam.run.sweep.simulate_cached`,
:func:`~sonarslam.slam.run.sweep.calibrate_cached`), then run (``sonarslam run WORLD --config
calibration.toml``, a process each, ``--workers`` at a time) with dead reckoning and with
``--backend`` (the factor graph by default) under each ``--variant`` (``NAME=`` alone: the
defaults). ``--noise-model FILE`` (e.g. ``benchmarks/marina_noise_model.toml``) is a partial
``sonarslam.toml`` laid over each world's calibration (the estimators told another noise model
than the world's own; written beside it as ``calibration+<stem>.toml``). Per variant, for the
online and (a smoother's) the smoothed estimates over the seeds: the mean ATE against the truth,
unaligned and SE(2)-aligned; the share of worlds where it beats dead reckoning, the count worse
than it by more than 10 % and the worst ``ATE / ATE_DR - 1``; the association precision and
recall against the true walls, pooled over the runs (every pairing weighs the same); the pose
ANEES (the mean over the runs of each run's mean NEES against the
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
import re
import subprocess
import sys
import warnings
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import Any

import numpy as np
import tomli_w

from sonarslam.datasets.errors import DataWarning
from sonarslam.datasets.toml import read_toml
from sonarslam.slam.eval.consistency import nees_series
from sonarslam.slam.eval.truth import calibration_sigmas, true_calibration
from sonarslam.slam.run.report_data import load_run
from sonarslam.slam.run.sweep import calibrate_cached, parse_seeds, simulate_cached

#: The estimates scored: label -> the metrics.json infix of its ATE keys (an estimate a run does
#: not make is left out: a filter's smoothed, a graph's offline before that estimate exists).
ESTIMATES = {"online": "", "smoothed": "_smoothed", "offline": "_offline"}
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


def with_noise_model(calibration: str, model: Path | None) -> str:
    """The world's calibration with ``model``'s tables laid over it (key by key), written beside
    it once; the calibration itself when ``model`` is None."""
    if model is None:
        return calibration
    path = Path(calibration).with_name(f"calibration+{model.stem}.toml")
    merged, _ = read_toml(calibration)
    extra, _ = read_toml(model)
    for table, keys in extra.items():
        merged[table] = {**merged.get(table, {}), **keys}
    text = tomli_w.dumps(merged)
    if not path.is_file() or path.read_text() != text:
        path.write_text(text)
    return str(path)


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
            "worst_vs_dr": float(np.max(u / dr_u - 1.0)),
            "worst_vs_dr_aligned": float(np.max(a / dr_a - 1.0)),
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
    n = np.array([runs[s].get("truth_associations", 0) or 0 for s in seeds], dtype=float)
    m = np.array([runs[s].get("truth_reobservations", 0) or 0 for s in seeds], dtype=float)
    prec = np.array([runs[s].get("truth_precision", 0.0) or 0.0 for s in seeds])
    rec = np.array([runs[s].get("truth_recall", 0.0) or 0.0 for s in seeds])
    prec, rec = np.nan_to_num(prec), np.nan_to_num(rec)
    out["precision"] = float((prec * n).sum() / max(n.sum(), 1.0))
    out["recall"] = float((rec * m).sum() / max(m.sum(), 1.0))
    out["pairings"] = int(n.sum())
    out["nees_per_seed"] = {s: float(x) for s, x in zip(seeds, nees, strict=True)}
    out["anees"] = float(np.mean(nees))
    out["nees_median"] = float(np.median(nees))
    out["nees_above_10"] = int(np.sum(np.array(nees) > 10.0))
    out["within_2sigma"] = {k: float(np.mean(v)) for k, v in within.items() if v}
    return out


def table(result: dict[str, Any]) -> str:
    rows = [
        "| variant | estimate | ATE mean / aligned (m) | beats DR / aligned | worse by > 10 %"
        " / aligned (worst) | ANEES (median; runs > 10) | precision / recall |"
        " within 2σ: x, y, yaw, range scale |",
        "|---|---|---|---|---|---|---|---|",
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
            pr = f"{100 * v['precision']:.2f} % / {100 * v['recall']:.2f} %"
            rows.append(
                f"| {name} | {label} | {e['ate_mean_m']:.2f} / {e['ate_aligned_mean_m']:.2f} | "
                f"{100 * e['beats_dr']:.0f} % / {100 * e['beats_dr_aligned']:.0f} % | "
                f"{e['worse_10pct']} / {e['worse_10pct_aligned']} ({100 * e['worst_vs_dr']:+.0f} %"
                f" / {100 * e['worst_vs_dr_aligned']:+.0f} %) | {nees} | "
                f"{pr if label == 'online' else ''} | {cal if label == 'online' else ''} |"
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
    ap.add_argument(
        "--noise-model",
        type=Path,
        default=None,
        metavar="FILE",
        help="a partial sonarslam.toml over each world's calibration (the noise model told)",
    )
    ap.add_argument("--out", type=Path, default=Path("out/drawn_defaults"))
    args = ap.parse_args(argv)
    variants: dict[str, list[str]] = {}
    for v in args.variant:
        name, _, sets = v.partition("=")
        # a comma starts the next setting only before SCOPE.FIELD= (a value may hold commas:
        # isam2.learn_noise=heading,lines)
        parts = re.split(r",(?=[A-Za-z_][\w.]*\.[\w]+=)", sets)
        variants[name] = [a for s in parts if s for a in ("--set", s)]
    seeds = parse_seeds(args.seeds)
    worlds = {}
    for s in seeds:
        folder = simulate_cached("drawn", s, None, args.cache)
        worlds[s] = (folder, with_noise_model(calibrate_cached(folder), args.noise_model))
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
        "noise_model": None if args.noise_model is None else str(args.noise_model),
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
