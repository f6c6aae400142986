"""The product's revisit registrations at a reference pose graph's pairs, against the reference's
own registrations and the GPS ruler.

python benchmarks/marina_reference_pairs.py \\
    [--reference ../shared/reference/marina-posegraph/factors-revisits-only.json] \\
    [--set scans.FIELD=V ...] [--out out/marina_reference_pairs.json]

The reference (``../shared/reference/marina-posegraph/``, README there; outside the product,
GPS-free) registered 235 revisits between the mid times of keyframe scans (its ``rev``: nodes
``i``, ``j`` at ``t_nodes``, the relative pose ``T = inverse(wTi) * wTj``). Here, for each of its
pairs:

1. The product's scans (:class:`sonarslam.features.scans.ScanMatcher`, motion-corrected with
   dead reckoning as in ``benchmarks/marina_registration.py``): the scan whose middle time is
   nearest each node time.
2. The product's own revisit registration of the two, submap to submap from several starts
   (:meth:`sonarslam.features.scans.ScanMatcher.register`), from dead reckoning's relative pose
   and its covariance (``S_k - S_j`` of its chain, as the registration benchmark's rule).
3. Re-expressed between the reference's node times with dead reckoning's relative motion between
   each node time and its scan's reference time (seconds: small and locally right), with its
   covariance carried along (``z_nodes``, ``cov_nodes`` in plain ``(x_m, y_m, yaw_rad)``: the
   family ``refpairs`` of ``benchmarks/marina_factor_levels.py --reference-pairs``).
4. Scored: against the ruler (GPS positions with the AHRS heading dead reckoning uses: the
   position error of the relative pose, p50, p90 and the share beyond 2 m), and against the
   reference's relative pose, for the product's accepted registrations and for the reference's
   own at the same pairs. Also, of the product's registrations that its gate accepted, those
   that a graph's compatibility gate would keep (chi2(3) 0.999 of the difference with dead
   reckoning's relative pose, both covariances; the graph's own prediction is tighter).

GPS is the ruler only; nothing here feeds an estimator.
"""

from __future__ import annotations

import common  # noqa: F401  # first: one BLAS thread  # isort: skip
from common import write_result  # isort: skip

import argparse
import json
import sys
import time
from collections import Counter
from pathlib import Path
from typing import Any

import numpy as np
from marina_registration import build_scans
from scipy.stats import chi2

from sonarslam.datasets.errors import DataError
from sonarslam.datasets.source import open_dataset
from sonarslam.features.geometry import between, compose, compose_jacobians, wrap_angle
from sonarslam.slam.run.presets import SCAN_PRESETS, apply_overrides, parse_settings, preset_for
from sonarslam.slam.run.sources import dead_reckoning_trajectory, gps_ahrs_trajectory

DEFAULT_REFERENCE = "../shared/reference/marina-posegraph/factors-revisits-only.json"


def quantiles(err_m: np.ndarray) -> dict[str, float]:
    """p50, p90 (m) and the share beyond 2 m of position errors."""
    if err_m.size == 0:
        return {"n": 0, "p50_m": float("nan"), "p90_m": float("nan"), "beyond_2m": float("nan")}
    return {
        "n": int(err_m.size),
        "p50_m": float(np.percentile(err_m, 50)),
        "p90_m": float(np.percentile(err_m, 90)),
        "beyond_2m": float(np.mean(err_m > 2.0)),
    }


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    ap.add_argument("--source", default="marina")
    ap.add_argument("--reference", type=Path, default=Path(DEFAULT_REFERENCE))
    ap.add_argument("--set", action="append", default=[], metavar="scans.FIELD=V")
    ap.add_argument("--out", type=Path, default=None, help="JSON of the scores and every pair")
    args = ap.parse_args(argv)
    try:
        ds = open_dataset(args.source)
        ref = json.loads(args.reference.read_text())
        t_nodes = np.asarray(ref["t_nodes"], dtype=np.float64)
        rev = ref["rev"]
    except (DataError, FileNotFoundError, ValueError, KeyError) as exc:
        print(f"marina_reference_pairs: {exc}", file=sys.stderr)
        return 1
    settings = parse_settings(args.set)
    bad = [k for k in settings if not k.startswith("scans.")]
    if bad:
        print(f"marina_reference_pairs: only scans.* settings, got {bad}", file=sys.stderr)
        return 1
    config = apply_overrides(
        SCAN_PRESETS[preset_for(ds.beams)],
        {k[len("scans.") :]: v for k, v in settings.items()},
    )
    dr = dead_reckoning_trajectory(ds)
    ruler = gps_ahrs_trajectory(ds)
    compat = float(chi2.ppf(0.999, 3))
    wall0 = time.perf_counter()
    matcher = build_scans(ds, config, dr)
    scans = matcher.scans
    t_mid = np.array([0.5 * (s.t_first_s + s.t_ref_s) for s in scans])
    t_ref = np.array([s.t_ref_s for s in scans])

    def scan_of(t: float) -> int:
        return int(np.argmin(np.abs(t_mid - t)))

    rows: list[dict[str, Any]] = []
    reasons: Counter[str] = Counter()
    for pair in rev:
        ti, tj = float(t_nodes[pair["i"]]), float(t_nodes[pair["j"]])
        a, b = scan_of(ti), scan_of(tj)
        Pa, Pb = dr.poses(np.array([t_ref[a], t_ref[b]]))
        Ca, Cb = dr.covariance(float(t_ref[a])), dr.covariance(float(t_ref[b]))
        S = np.diag([1.0, 1.0, 1e-4]) if Ca is None or Cb is None else np.abs(Cb - Ca)
        reg = matcher.register(a, b, between(Pa, Pb), S)
        reasons[reg.reason or "accepted"] += 1
        # node i -> scan a's reference, scan b's reference -> node j (dead reckoning's motion)
        Pi, Pj = dr.poses(np.array([ti, tj]))
        iTa = compose(between(Pi, Pa), reg.z)
        z = compose(iTa, between(Pb, Pj))
        _, J1_z = compose_jacobians(between(Pi, Pa), reg.z)
        J2_a, _ = compose_jacobians(iTa, between(Pb, Pj))
        J = J2_a @ J1_z  # d z / d reg.z
        g = between(*ruler.poses(np.array([ti, tj])))
        T_ref = np.asarray(pair["T"], dtype=np.float64)
        nu = np.array(
            [*(reg.z[:2] - between(Pa, Pb)[:2]), wrap_angle(reg.z[2] - between(Pa, Pb)[2])]
        )
        nis = float(nu @ np.linalg.solve(S + reg.cov, nu))
        rows.append(
            {
                "i": pair["i"],
                "j": pair["j"],
                "scan_a": a,
                "scan_b": b,
                "accepted": bool(reg.accepted),
                "reason": reg.reason,
                "compatible": bool(reg.accepted and nis <= compat),
                "nis_dr": nis,
                "z_nodes": z.tolist(),
                "cov_nodes": (J @ reg.cov @ J.T).tolist(),
                "err_gps_m": float(np.hypot(*(z[:2] - g[:2]))),
                "err_gps_yaw_deg": float(np.degrees(abs(wrap_angle(z[2] - g[2])))),
                "err_reference_m": float(np.hypot(*(z[:2] - T_ref[:2]))),
                "reference_err_gps_m": float(np.hypot(*(T_ref[:2] - g[:2]))),
                "dr_err_gps_m": float(np.hypot(*(between(Pi, Pj)[:2] - g[:2]))),
                "inlier_share": reg.inlier_share,
                "n_constrained": reg.n_constrained,
                "sigma_m": reg.sigma_m,
            }
        )
    wall = time.perf_counter() - wall0

    def col(key: str, sel: Any) -> np.ndarray:
        return np.array([r[key] for r in rows if sel(r)])

    every, acc, kept = (lambda r: True), (lambda r: r["accepted"]), (lambda r: r["compatible"])
    result = {
        "source": str(ds.root),
        "reference": str(args.reference),
        "pairs": len(rows),
        "accepted": int(sum(r["accepted"] for r in rows)),
        "compatible": int(sum(r["compatible"] for r in rows)),
        "rejected": dict(sorted((k, v) for k, v in reasons.items() if k != "accepted")),
        "reference_vs_gps": quantiles(col("reference_err_gps_m", every)),
        "dead_reckoning_vs_gps": quantiles(col("dr_err_gps_m", every)),
        "product_vs_gps_accepted": quantiles(col("err_gps_m", acc)),
        "product_vs_gps_compatible": quantiles(col("err_gps_m", kept)),
        "product_vs_gps_all": quantiles(col("err_gps_m", every)),
        "reference_vs_gps_where_accepted": quantiles(col("reference_err_gps_m", acc)),
        "product_vs_reference_accepted": quantiles(col("err_reference_m", acc)),
        "product_yaw_vs_gps_p50_deg": float(np.median(col("err_gps_yaw_deg", acc)))
        if any(r["accepted"] for r in rows)
        else float("nan"),
        "settings": {k: str(v) for k, v in settings.items()},
        "wall_s": wall,
        "rows": rows,
    }
    f = "{n} pairs: p50 {p50_m:.2f} / p90 {p90_m:.2f} m / {beyond_2m:.1%} beyond 2 m"
    print(
        f"{result['pairs']} reference pairs, {result['accepted']} accepted by the product's gate "
        f"({result['compatible']} compatible with dead reckoning), rejected {result['rejected']}, "
        f"{wall:.0f} s"
    )
    for key in (
        "reference_vs_gps",
        "dead_reckoning_vs_gps",
        "product_vs_gps_accepted",
        "product_vs_gps_compatible",
        "product_vs_gps_all",
        "reference_vs_gps_where_accepted",
        "product_vs_reference_accepted",
    ):
        print(f"  {key:34s} {f.format(**result[key])}")
    write_result(result, args.out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
