"""Scan registration on the marina (or a simulated run) against a ruler: GPS + AHRS on the
marina, the simulator's truth on simulated data. The ruler measures only.

python benchmarks/marina_registration.py [--source marina|DIR] [--set scans.FIELD=V ...] \\
    [--submaps 1,3,5] [--out out/marina_registration.json]

1. **Scans** (:class:`sonarslam.features.scans.ScanMatcher`): every full turn of the head, leading edges
   motion-corrected with **dead reckoning** (GPS-free, as a closed loop's first pass).
2. **Consecutive pairs**: each scan registered onto the one before it, from dead reckoning's
   relative pose.
3. **Revisit pairs**: scans at least ``--min-gap`` s apart whose dead-reckoning positions are
   within ``revisit_radius_m`` (10 m) up to the chi2(1) 0.99 gate of dead reckoning's relative
   position covariance (``S_k - S_j`` of its growing chain), the nearest two per scan (a
   submap apart), registered as submaps of ``submap_scans`` scans from several starts along
   that covariance (:func:`sonarslam.features.scans.icp.register_from`) - the rule of the factor graph
   (:mod:`sonarslam.slam.backends.isam2.scans`), with dead reckoning in place of its marginals.
4. **GPS-free**: the accepted revisits at most ``--short-gap`` s apart (200) against dead
   reckoning's relative pose, whose covariance over so short a time is small and known: the NIS
   of their difference and the factor on the registrations' covariance that makes its median
   chi2(3)'s (``scans.revisit_cov_scale``).
5. With ``--submaps N1,N2,...`` the revisits are registered once per submap size (``1``: scan
   to scan, one full turn each; ``3``: three consecutive scans each, the factor graph's), the
   same pairs each time, and a row is printed per size.
6. **Scores** per kind: pairs, accepted, rejected by reason; of the accepted, the position
   error of the registration and of dead reckoning's guess against the ruler's relative pose
   (p50, p90, share beyond 2 m), the error in the directions the registration constrains, and
   the NEES of the registration (3 dof, its own covariance; the ruler's own error is not added,
   so on the marina it is an upper bound).
"""

from __future__ import annotations

import common  # noqa: F401  # first: one BLAS thread  # isort: skip
from common import write_result  # isort: skip

import argparse
import sys
import time
from collections import Counter
from pathlib import Path
from typing import Any

import numpy as np
from scipy.stats import chi2

from sonarslam.datasets.errors import DataError
from sonarslam.datasets.source import Dataset, open_dataset
from sonarslam.features.geometry import between, wrap_angle
from sonarslam.features.scans import Registration, ScanConfig, ScanMatcher  # noqa: F401
from sonarslam.slam.backends.isam2.scans import radial_gate_distance
from sonarslam.slam.eval.consistency import mean_nees_band
from sonarslam.slam.eval.truth import truth_trajectory
from sonarslam.slam.io.trajectory import Trajectory
from sonarslam.slam.run.presets import SCAN_PRESETS, apply_overrides, parse_settings, preset_for
from sonarslam.slam.run.sources import dead_reckoning_trajectory, gps_ahrs_trajectory

GATE_CHI2_1 = 6.635  # chi2(1) at 0.99


def build_scans(ds: Dataset, config: ScanConfig, poses: Trajectory) -> ScanMatcher:
    """Every scan of the navigation span, motion-corrected with ``poses``."""
    t0, t1 = poses.span_s
    matcher = ScanMatcher(config, ds.config.sonar, ds.config.sonar_mounting, poses)
    for beam in ds.beams:
        if t0 <= beam.t <= t1:
            matcher.add(beam)
    return matcher


def revisit_pairs(
    matcher: ScanMatcher, dr: Trajectory, radius_m: float, min_gap_s: float, per_scan: int
) -> list[tuple[int, int, np.ndarray]]:
    """``(j, k, S)``: the revisit candidates of step 3 with dead reckoning's relative covariance."""
    t = np.array([s.t_ref_s for s in matcher.scans])
    P = dr.poses(t)
    covs = [dr.covariance(float(x)) for x in t]
    out = []
    for k in range(t.size):
        cands = []
        for j in range(k):
            if t[k] - t[j] < min_gap_s:
                continue
            Ck, Cj = covs[k], covs[j]
            S = np.diag([1.0, 1.0, 1e-4]) if Ck is None or Cj is None else np.abs(Ck - Cj)
            g = radial_gate_distance(P[k, :2] - P[j, :2], S[:2, :2], radius_m)
            if g <= GATE_CHI2_1:
                cands.append((g, j, S))
        chosen: list[int] = []
        for _, j, S in sorted(cands, key=lambda c: c[0]):
            if len(chosen) >= per_scan:
                break
            if any(abs(j - c) < matcher.config.submap_scans for c in chosen):
                continue
            chosen.append(j)
            out.append((j, k, S))
    return out


def _q(x: np.ndarray) -> dict[str, float]:
    if x.size == 0:
        return {"p50_m": float("nan"), "p90_m": float("nan"), "beyond_2m": float("nan")}
    return {
        "p50_m": float(np.percentile(x, 50)),
        "p90_m": float(np.percentile(x, 90)),
        "beyond_2m": float(np.mean(x > 2.0)),
    }


def score(
    rows: list[tuple[Registration, np.ndarray]],
    ruler: Trajectory,
    t_pairs: list[tuple[float, float]],
) -> dict[str, Any]:
    """Step 4 for one kind of pairs."""
    err, err_guess, err_c, nees, reasons = [], [], [], [], Counter()
    for (reg, _), (tj, tk) in zip(rows, t_pairs, strict=True):
        reasons[reg.reason or "accepted"] += 1
        if not reg.accepted:
            continue
        g = between(*ruler.poses(np.array([tj, tk])))
        d = np.array([*(reg.z[:2] - g[:2]), wrap_angle(reg.z[2] - g[2])])
        err.append(np.hypot(d[0], d[1]))
        err_guess.append(np.hypot(*(reg.guess[:2] - g[:2])))
        scaled = np.array([d[0], d[1], reg.length_m * d[2]])
        proj = reg.constrained @ (reg.constrained.T @ scaled)
        err_c.append(np.hypot(proj[0], proj[1]))
        nees.append(float(d @ np.linalg.solve(reg.cov, d)))
    n_acc = len(err)
    lo, hi = mean_nees_band(max(n_acc, 1), 3)
    return {
        "pairs": len(rows),
        "accepted": n_acc,
        "rejected": dict(sorted((k, v) for k, v in reasons.items() if k != "accepted")),
        "registration": _q(np.array(err)),
        "registration_constrained": _q(np.array(err_c)),
        "dead_reckoning_guess": _q(np.array(err_guess)),
        "nees_mean": float(np.mean(nees)) if nees else float("nan"),
        "nees_median": float(np.median(nees)) if nees else float("nan"),
        "nees_band_95": [lo, hi],
    }


def short_revisit_consistency(
    rows: list[tuple[Registration, np.ndarray]],
    t_pairs: list[tuple[float, float]],
    dr: Trajectory,
    max_gap_s: float,
) -> dict[str, Any]:
    """GPS-free: accepted revisits at most ``max_gap_s`` apart against dead reckoning's relative
    pose, whose covariance over so short a time is small and known (``S_k - S_j`` of its chain,
    in scan j's frame). The NIS of their difference with the sum of the two covariances, and the
    factor on the registrations' covariance that brings its median to chi2(3)'s (a revisit's
    systematic error beyond the floor measured on consecutive scans)."""
    diffs = []
    for (reg, _), (tj, tk) in zip(rows, t_pairs, strict=True):
        if not reg.accepted or tk - tj > max_gap_s or reg.n_constrained < 3:
            continue
        Cj, Ck = dr.covariance(tj), dr.covariance(tk)
        if Cj is None or Ck is None:
            continue
        dS = 0.5 * ((Ck - Cj) + (Ck - Cj).T)
        w, v = np.linalg.eigh(dS)
        dS = (v * np.clip(w, 1e-10, None)) @ v.T
        pj, pk = dr.poses(np.array([tj, tk]))
        c, s = np.cos(pj[2]), np.sin(pj[2])
        rot = np.array([[c, s, 0.0], [-s, c, 0.0], [0.0, 0.0, 1.0]])
        d = between(pj, pk)
        nu = np.array([*(reg.z[:2] - d[:2]), wrap_angle(reg.z[2] - d[2])])
        diffs.append((nu, rot @ dS @ rot.T, reg.cov))
    target = float(chi2.ppf(0.5, 3))

    def median_nis(scale: float) -> float:
        return float(np.median([nu @ np.linalg.solve(S + scale * C, nu) for nu, S, C in diffs]))

    if len(diffs) < 10:
        return {"pairs": len(diffs), "nis_median": float("nan"), "cov_scale": float("nan")}
    scales = np.geomspace(0.25, 64.0, 97)
    nis = np.array([median_nis(x) for x in scales])
    above = np.flatnonzero(nis <= target)
    scale = float(scales[above[0]]) if above.size else float("inf")
    return {
        "pairs": len(diffs),
        "max_gap_s": max_gap_s,
        "nis_median": median_nis(1.0),
        "chi2_3_median": target,
        "cov_scale": scale,
    }


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    ap.add_argument("--source", default="marina", help="marina or a dataset directory")
    ap.add_argument("--set", action="append", default=[], metavar="scans.FIELD=V")
    ap.add_argument("--radius", type=float, default=10.0, help="revisit radius (m)")
    ap.add_argument("--min-gap", type=float, default=60.0, help="revisit time gap (s)")
    ap.add_argument("--per-scan", type=int, default=2, help="revisits per scan")
    ap.add_argument(
        "--submaps",
        default=None,
        help="comma list of submap sizes (odd scans) to register the same revisits with, e.g. 1,3,5",
    )
    ap.add_argument(
        "--short-gap",
        type=float,
        default=200.0,
        help="revisits at most this far apart (s) are scored against dead reckoning (GPS-free)",
    )
    ap.add_argument("--out", type=Path, default=None, help="JSON of the scores")
    args = ap.parse_args(argv)
    try:
        ds = open_dataset(args.source)
    except (DataError, FileNotFoundError, ValueError) as exc:
        print(f"marina_registration: {exc}", file=sys.stderr)
        return 1
    settings = parse_settings(args.set)
    bad = [k for k in settings if not k.startswith("scans.")]
    if bad:
        print(f"marina_registration: only scans.* settings, got {bad}", file=sys.stderr)
        return 1
    preset = SCAN_PRESETS[preset_for(ds.beams)]  # as the closed loop's
    config = apply_overrides(preset, {k[len("scans.") :]: v for k, v in settings.items()})
    simulated = ds.truth is not None
    ruler = truth_trajectory(ds) if simulated else gps_ahrs_trajectory(ds)
    dr = dead_reckoning_trajectory(ds)
    wall0 = time.perf_counter()
    matcher = build_scans(ds, config, dr)
    scans = matcher.scans
    consecutive = [matcher.consecutive(k) for k in range(1, len(scans))]
    cons_rows = [(r, np.zeros(3)) for r in consecutive if r is not None]
    cons_t = [(scans[k - 1].t_ref_s, scans[k].t_ref_s) for k in range(1, len(scans))]
    pairs = revisit_pairs(matcher, dr, args.radius, args.min_gap, args.per_scan)
    rev_t = [(scans[j].t_ref_s, scans[k].t_ref_s) for j, k, _ in pairs]
    sizes = (
        [config.submap_scans] if args.submaps is None else [int(v) for v in args.submaps.split(",")]
    )
    by_size: dict[int, dict[str, Any]] = {}
    for n in sizes:
        sized = (
            matcher
            if n == config.submap_scans
            else build_scans(ds, config.replace(submap_scans=n), dr)
        )
        rows = []
        for j, k, S in pairs:
            guess = between(*dr.poses(np.array([scans[j].t_ref_s, scans[k].t_ref_s])))
            rows.append((sized.register(j, k, guess, S), S))
        by_size[n] = score(rows, ruler, rev_t)
        by_size[n]["short_revisits_vs_dead_reckoning"] = short_revisit_consistency(
            rows, rev_t, dr, args.short_gap
        )
    wall = time.perf_counter() - wall0
    result = {
        "source": str(ds.root),
        "ruler": "truth" if simulated else "gps+ahrs",
        "scans": len(scans),
        "points_per_scan_median": float(np.median([s.points_b.shape[0] for s in scans])),
        "consecutive": score(cons_rows, ruler, cons_t),
        "revisit": by_size[sizes[0]],
        "revisit_by_submap_scans": {str(n): v for n, v in by_size.items()},
        "revisit_rule": {
            "radius_m": args.radius,
            "min_gap_s": args.min_gap,
            "per_scan": args.per_scan,
        },
        "config": config.to_dict(),
        "wall_s": wall,
    }
    print(
        f"{result['source']} ({result['ruler']} as ruler): {len(scans)} scans, "
        f"{result['points_per_scan_median']:.0f} points each, {wall:.1f} s"
    )
    print(
        "| pairs | tried | accepted | registration p50 / p90 / >2 m | constrained directions"
        " | dead reckoning | NEES mean [95 % band] | rejected |"
    )
    print("|---|---|---|---|---|---|---|---|")
    rows_out = [("consecutive scans", result["consecutive"])]
    rows_out += [
        (f"revisits, submaps of {n} scan{'s' if n > 1 else ''}", v) for n, v in by_size.items()
    ]
    for kind, s in rows_out:
        f = "{p50_m:.2f} / {p90_m:.2f} / {beyond_2m:.0%}"
        print(
            f"| {kind} | {s['pairs']} | {s['accepted']} | {f.format(**s['registration'])} | "
            f"{f.format(**s['registration_constrained'])} | {f.format(**s['dead_reckoning_guess'])} | "
            f"{s['nees_mean']:.2f} [{s['nees_band_95'][0]:.2f}, {s['nees_band_95'][1]:.2f}] | "
            f"{', '.join(f'{k} {v}' for k, v in s['rejected'].items())} |"
        )
    for n, v in by_size.items():
        c = v["short_revisits_vs_dead_reckoning"]
        print(
            f"GPS-free, submaps of {n}: {c['pairs']} revisits at most {args.short_gap:g} s apart"
            f" against dead reckoning: NIS median {c['nis_median']:.2f} (chi2(3): 2.37); their"
            f" covariance x{c['cov_scale']:.2f} makes it chi2(3)'s (scans.revisit_cov_scale)"
        )
    write_result(result, args.out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
