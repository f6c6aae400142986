"""Statistics of the line extractor on the simulator, which knows the right answer.

a. The seed paper's pool test (Song et al. 2010, section 3) over many seeds:
   ``make_scenario("pool", seed)``, a stationary sonar in a 2 m x 4 m pool, 6 m range, 0.45 deg step,
   a 270 deg sector, beta 25 deg, min votes 15 (:func:`sonarslam.slam.eval.lines.pool_config`); one vote per
   full sector, four per run. Reports the fraction of seeds whose every vote finds all four walls
   (required >= 95 %), and the RMS errors of ``rho`` (required < 5 cm) and ``theta`` (< 1 deg) of
   the features against the true walls, in each feature's frame R, sign-free.
b. Honest covariance: the mean NEES of ``(rho, theta)`` of the pool's features and of a harbour
   survey's (a vehicle moving at 0.45 m/s, raw beams, the extractor's defaults), against the
   95 % band of the mean of N chi2(2) variables, ``chi2.ppf([0.025, 0.975], 2 N) / N``; for both
   covariance methods, "fit" and "seed".
c. Honest lines on thick echo bands: the drift world (echoes peak 0.25 m behind the walls), the
   extractor's defaults, before and after the GPS-free sonar calibration that
   ``sonarslam sweep --calibrate`` applies (range offset, then the lines' systematic error): their
   mean rho error and NEES against the true walls, against the same band.

Poses are the simulator's truth, so the NEES measures the front end alone.

Usage::

    .venv/bin/python benchmarks/extractor_consistency.py --out out/extractor_consistency.json
"""

from __future__ import annotations

import argparse
import json
import sys
import time
import tomllib
from collections.abc import Sequence
from dataclasses import fields
from pathlib import Path
from typing import Any

import numpy as np
from tqdm import tqdm

from sonarslam.features.config import ExtractorConfig
from sonarslam.slam.eval.consistency import mean_nees_band
from sonarslam.slam.run.line_trials import TrialResult, drift_trial, harbour_trial, pool_trial

METHODS = ("fit", "seed")
POOL_WALL_SEED_FRACTION_MIN = 0.95
POOL_RMS_RHO_MAX_M = 0.05
POOL_RMS_THETA_MAX_RAD = float(np.deg2rad(1.0))
CHI2_95_2DOF = 5.991


def nees_summary(nees: np.ndarray) -> dict[str, Any]:
    """Mean NEES of N detections, its 95 % band, and the tail fraction."""
    n = int(nees.size)
    lo, hi = mean_nees_band(n, 2)
    mean = float(nees.mean())
    return {
        "n": n,
        "mean": mean,
        "band_95": [lo, hi],
        "inside_band": bool(lo <= mean <= hi),
        "verdict": "consistent"
        if lo <= mean <= hi
        else ("optimistic" if mean > hi else "pessimistic"),
        "median": float(np.median(nees)),
        "fraction_above_chi2_95": float(np.mean(nees > CHI2_95_2DOF)),
    }


def pool_summary(results: list[TrialResult]) -> dict[str, Any]:
    """Pool figures of one method over its seeds."""
    errors = np.concatenate([r.errors for r in results])
    seeds_ok = sum(r.votes_all_walls == r.n_votes for r in results)
    return {
        "seeds": len(results),
        "seeds_all_walls_every_vote": seeds_ok,
        "fraction_seeds_all_walls": seeds_ok / len(results),
        "votes": sum(r.n_votes for r in results),
        "votes_all_walls": sum(r.votes_all_walls for r in results),
        "features": sum(r.n_features for r in results),
        "false_features": sum(r.n_false for r in results),
        "duplicate_features": sum(r.n_duplicates for r in results),
        "rms_rho_m": float(np.sqrt(np.mean(errors[:, 0] ** 2))),
        "rms_theta_rad": float(np.sqrt(np.mean(errors[:, 1] ** 2))),
        "mean_rho_error_m": float(errors[:, 0].mean()),
    }


def run(
    pool_seeds: int,
    harbour_seeds: int,
    harbour_duration_s: float | None,
    config_changes: dict[str, Any] | None = None,
    drift_seeds: int = 0,
    drift_duration_s: float | None = None,
) -> dict[str, Any]:
    """All trials and their summaries (the JSON written by :func:`main`); ``config_changes``
    replace fields of the extractor's configuration in the pool and the harbour."""
    wall0 = time.perf_counter()
    pool: dict[str, list[TrialResult]] = {m: [] for m in METHODS}
    harbour: dict[str, list[TrialResult]] = {m: [] for m in METHODS}
    for seed in tqdm(range(pool_seeds), desc="pool", unit="seed"):
        for r in pool_trial(seed, METHODS, config_changes):
            pool[r.method].append(r)
    for seed in tqdm(range(harbour_seeds), desc="harbour", unit="seed"):
        for r in harbour_trial(seed, METHODS, harbour_duration_s, config_changes):
            harbour[r.method].append(r)
    out: dict[str, Any] = {
        "pool_seeds": pool_seeds,
        "harbour_seeds": harbour_seeds,
        "harbour_duration_s": harbour_duration_s,
        "config_changes": config_changes or {},
        "pool": {m: pool_summary(pool[m]) for m in METHODS},
        "nees": {},
    }
    for m in METHODS:
        p = np.concatenate([r.nees for r in pool[m]])
        h = np.concatenate([r.nees for r in harbour[m]]) if harbour_seeds else np.zeros(0)
        h_err = (
            np.concatenate([r.errors for r in harbour[m]]) if harbour_seeds else np.zeros((0, 2))
        )
        out["nees"][m] = {
            "pool": nees_summary(p),
            "harbour": nees_summary(h) if h.size else None,
            "all": nees_summary(np.concatenate([p, h])),
            "harbour_features": sum(r.n_features for r in harbour[m]),
            "harbour_false_features": sum(r.n_false for r in harbour[m]),
            "harbour_mean_rho_error_m": float(h_err[:, 0].mean()) if h.size else None,
        }
    drift: dict[str, list[TrialResult]] = {"raw": [], "calibrated": []}
    for seed in tqdm(range(drift_seeds), desc="drift", unit="seed"):
        for r in drift_trial(seed, drift_duration_s):
            drift[r.method].append(r)
    out["drift_seeds"] = drift_seeds
    out["drift_duration_s"] = drift_duration_s
    out["drift"] = {
        m: {
            **nees_summary(np.concatenate([r.nees for r in rs])),
            "features": sum(r.n_features for r in rs),
            "false_features": sum(r.n_false for r in rs),
            "mean_rho_error_m": float(np.concatenate([r.errors for r in rs])[:, 0].mean()),
            "seeds_inside_band": sum(
                bool(mean_nees_band(r.nees.size, 2)[0] <= r.nees.mean())
                and bool(r.nees.mean() <= mean_nees_band(r.nees.size, 2)[1])
                for r in rs
            ),
        }
        for m, rs in drift.items()
        if rs
    }
    fit = out["pool"]["fit"]
    out["pool_requirements"] = {
        "fraction_seeds_all_walls": fit["fraction_seeds_all_walls"] >= POOL_WALL_SEED_FRACTION_MIN,
        "rms_rho": fit["rms_rho_m"] < POOL_RMS_RHO_MAX_M,
        "rms_theta": fit["rms_theta_rad"] < POOL_RMS_THETA_MAX_RAD,
    }
    out["wall_s"] = time.perf_counter() - wall0
    return out


def format_table(res: dict[str, Any]) -> str:
    """The figures as a small text table."""
    rows = [
        f"pool test, {res['pool_seeds']} seeds x 4 votes (270 deg sectors), truth poses"
        + (f"; config changes {res['config_changes']}" if res["config_changes"] else ""),
        f"{'method':6s} {'seeds all 4 walls':>18s} {'votes all 4':>12s} {'features':>8s} "
        f"{'false':>5s} {'dup':>4s} {'RMS rho (cm)':>12s} {'RMS theta (deg)':>15s}",
    ]
    for m, p in res["pool"].items():
        rows.append(
            f"{m:6s} {p['seeds_all_walls_every_vote']:>8d}/{p['seeds']:<3d}({100 * p['fraction_seeds_all_walls']:5.1f} %)"
            f" {p['votes_all_walls']:>5d}/{p['votes']:<6d} {p['features']:>8d} {p['false_features']:>5d}"
            f" {p['duplicate_features']:>4d} {100 * p['rms_rho_m']:>12.3f} {np.rad2deg(p['rms_theta_rad']):>15.3f}"
        )
    rows += [
        "",
        f"NEES of (rho, theta) against the true walls (pool; harbour {res['harbour_seeds']} seeds)",
        f"{'method':6s} {'set':8s} {'N':>5s} {'mean NEES':>9s} {'95 % band':>14s} {'verdict':>11s}"
        f" {'median':>6s} {'P>5.99':>6s}",
    ]
    for m, by_set in res["nees"].items():
        for name in ("pool", "harbour", "all"):
            s = by_set[name]
            if s is None:
                continue
            rows.append(
                f"{m:6s} {name:8s} {s['n']:>5d} {s['mean']:>9.2f} "
                f"[{s['band_95'][0]:.2f}, {s['band_95'][1]:.2f}] {s['verdict']:>11s}"
                f" {s['median']:>6.2f} {s['fraction_above_chi2_95']:>6.3f}"
            )
    if res["drift"]:
        rows += [
            "",
            f"drift world, {res['drift_seeds']} seeds, truth poses: GPS-free sonar calibration",
            f"{'lines':10s} {'N':>5s} {'rho err (m)':>11s} {'mean NEES':>9s} {'95 % band':>14s}"
            f" {'verdict':>11s} {'median':>6s} {'P>5.99':>6s} {'seeds in band':>13s}",
        ]
        for m, s in res["drift"].items():
            rows.append(
                f"{m:10s} {s['n']:>5d} {s['mean_rho_error_m']:>+11.3f} {s['mean']:>9.2f} "
                f"[{s['band_95'][0]:.2f}, {s['band_95'][1]:.2f}] {s['verdict']:>11s} {s['median']:>6.2f}"
                f" {s['fraction_above_chi2_95']:>6.3f} {s['seeds_inside_band']:>6d}/{res['drift_seeds']}"
            )
    rows.append(
        "(a consistent set would have: mean NEES inside its band, median 1.39, P>5.99 = 0.05;"
        " pessimistic = cautious)"
    )
    return "\n".join(rows)


def parse_changes(items: Sequence[str]) -> dict[str, Any]:
    """``FIELD=VALUE`` items (values in TOML syntax) as ExtractorConfig changes."""
    known = {f.name for f in fields(ExtractorConfig)}
    out: dict[str, Any] = {}
    for item in items:
        key, sep, value = item.partition("=")
        if not sep or key.strip() not in known:
            raise SystemExit(f"--set needs FIELD=VALUE with an ExtractorConfig field, got {item!r}")
        out[key.strip()] = tomllib.loads(f"v = {value}")["v"]
    return out


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--pool-seeds", type=int, default=50, help="pool seeds (default 50)")
    p.add_argument("--harbour-seeds", type=int, default=6, help="harbour seeds (default 6)")
    p.add_argument(
        "--harbour-duration",
        type=float,
        default=None,
        help="seconds of harbour survey per seed (default: the scenario's 600 s)",
    )
    p.add_argument("--drift-seeds", type=int, default=10, help="drift-world seeds (default 10)")
    p.add_argument(
        "--drift-duration",
        type=float,
        default=None,
        help="seconds of drift-world survey per seed (default: the scenario's 1,800 s)",
    )
    p.add_argument(
        "--set",
        action="append",
        default=[],
        metavar="FIELD=VALUE",
        help="change an ExtractorConfig field in the pool and the harbour (TOML value), e.g. "
        "range_offset_sigma_m=0 or remove_on_line_sigma=0; repeatable",
    )
    p.add_argument("--out", default="out/extractor_consistency.json", help="results JSON")
    return p


def main(argv: Sequence[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    changes = parse_changes(args.set)
    res = run(
        args.pool_seeds,
        args.harbour_seeds,
        args.harbour_duration,
        changes or None,
        args.drift_seeds,
        args.drift_duration,
    )
    print(format_table(res))
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(res, indent=2) + "\n")
    print(f"results: {out.resolve()} ({res['wall_s']:.0f} s)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
