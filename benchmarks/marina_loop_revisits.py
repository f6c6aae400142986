"""The factor graph's own revisits, each scored against a ruler: which of them are wrong, whether
their errors are shared, whether their covariance holds them, and what the compatibility gate
rejected. A benchmark only: the ruler (GPS + AHRS on the marina, the simulator's truth on
simulated data) never feeds an estimator.

python benchmarks/marina_loop_revisits.py [--source marina|DIR] [--set SCOPE.FIELD=V ...] \\
    [--run-out DIR] [--block-s 150] [--out out/marina_loop_revisits.json]

1. Runs the iSAM2 closed loop with scan constraints (``isam2.constraints = lines,scans`` unless
   ``--set`` says otherwise; ``--batch``: with its final batch pass) and, with ``--run-out``,
   writes its run directory (for ``benchmarks/marina_factor_levels.py``).
2. Takes every revisit registration the loop tried (its
   :class:`sonarslam.slam.backends.isam2.scans.ScanLog`): scans ``j``, ``k``, the registration
   ``z = jTk`` with its covariance, the graph's prediction ``jTk`` when it was tried (the guess),
   the registration's own verdict and the compatibility gate's.
3. Scores each against the ruler's relative pose between the two scans' reference times: the
   position error of the registration and of the graph's prediction (m), the error vector in
   the world frame (east, north: the ruler's heading at ``j`` turns it), the yaw error (deg) and
   the NEES of the registration with its own covariance (3 dof; the ruler's own error is not
   added, so on the marina it is an upper bound).
4. Summarises: per verdict (accepted, rejected by the gate, rejected by the registration) p50,
   p90, the share beyond 2 m, the mean world error vector and the NEES median; per pair of time
   blocks (``--block-s``), the count and the mean world error vector with its scatter (a shared
   error is a mean far from zero with a small scatter); the accepted revisits off by more than 2 m.
5. With ``--dead-reckoning``, each pair registered again as ``benchmarks/marina_reference_pairs.py``
   registers the reference's: scans motion-corrected with dead reckoning, every submap complete
   and centred, from dead reckoning's relative pose and covariance; scored the same way
   (``dr_*``): whether the loop's pairs or the loop's way of registering them are wrong.
6. With ``--oracle``, the pairs alone: the run's ``graph.json`` re-optimised
   (``benchmarks/marina_factor_levels.py``'s Levenberg-Marquardt) with its dead-reckoning and
   heading factors and, on the nodes nearest each pair's two times, the ruler's relative pose
   (sigma 0.3 m, 3 deg, Cauchy k = 1) for the accepted pairs, the accepted and the gate's
   rejects, and every pair tried: how much the choice of pairs and the gate cost when every
   registration is exact.
"""

from __future__ import annotations

import common  # noqa: F401  # first: one BLAS thread  # isort: skip
from common import write_result  # isort: skip

import argparse
import sys
import tempfile
import time
from collections import Counter, defaultdict
from pathlib import Path
from typing import Any

import numpy as np
from marina_factor_levels import family_of, load_run, node_trajectory, optimise, ruler_of, scores
from marina_registration import build_scans

from sonarslam.datasets.errors import DataError
from sonarslam.datasets.source import Dataset, open_dataset
from sonarslam.features.geometry import between, compose, wrap_angle
from sonarslam.features.scans import ScanConfig
from sonarslam.slam.backends.isam2.graph import LineIsam2
from sonarslam.slam.backends.isam2.graph_io import FactorKind, FactorRecord, Robust, key_of
from sonarslam.slam.eval.truth import truth_trajectory
from sonarslam.slam.io.trajectory import Trajectory
from sonarslam.slam.run.presets import parse_settings
from sonarslam.slam.run.run import run
from sonarslam.slam.run.sources import dead_reckoning_trajectory, gps_ahrs_trajectory

GATE_REJECT = "incompatible with the graph"


def errors(
    z: np.ndarray, t_j: float, t_k: float, ruler: Trajectory
) -> tuple[np.ndarray, np.ndarray]:
    """``(d, e_w)``: ``z - jTk`` of the ruler ``(x_m, y_m, yaw_rad)`` in j's frame and its
    position part in the world frame (east, north; the ruler's heading at j)."""
    wj, wk = ruler.poses(np.array([t_j, t_k]))
    g = between(wj, wk)
    d = np.array([*(z[:2] - g[:2]), wrap_angle(z[2] - g[2])])
    c, s = np.cos(wj[2]), np.sin(wj[2])
    return d, np.array([c * d[0] - s * d[1], s * d[0] + c * d[1]])


def score_pairs(pairs: list[dict[str, Any]], ruler: Trajectory) -> list[dict[str, Any]]:
    """Step 3: each revisit of a ``ScanLog`` with its errors against ``ruler``."""
    rows = []
    for p in pairs:
        if p["kind"] != "revisit":
            continue
        z, guess = np.asarray(p["z"]), np.asarray(p["guess"])
        d, e_w = errors(z, p["t_j"], p["t_k"], ruler)
        g, _ = errors(guess, p["t_j"], p["t_k"], ruler)
        cov = np.asarray(p["cov"])
        verdict = (
            "accepted"
            if p["accepted"]
            else ("gate" if p["reason"] == GATE_REJECT else "registration")
        )
        try:
            nees = float(d @ np.linalg.solve(cov, d))
        except np.linalg.LinAlgError:
            nees = float("nan")
        rows.append(
            {
                "j": p["j"],
                "k": p["k"],
                "t_j": p["t_j"],
                "t_k": p["t_k"],
                "verdict": verdict,
                "reason": p["reason"],
                "nis_graph": p["nis"],
                "n_constrained": p["n_constrained"],
                "err_m": float(np.hypot(d[0], d[1])),
                "err_yaw_deg": float(np.degrees(abs(d[2]))),
                "err_east_m": float(e_w[0]),
                "err_north_m": float(e_w[1]),
                "guess_err_m": float(np.hypot(g[0], g[1])),
                "nees": nees,
                "sigma_pos_m": float(np.sqrt(max(np.linalg.eigvalsh(cov[:2, :2]).max(), 0.0))),
            }
        )
    return rows


def redo_with_dead_reckoning(ds: Dataset, config: ScanConfig, rows: list[dict[str, Any]]) -> None:
    """Step 5: ``dr_z``, ``dr_accepted`` on each row (in place), scans matched by time."""
    dr = dead_reckoning_trajectory(ds)
    matcher = build_scans(ds, config, dr)
    t_ref = np.array([s.t_ref_s for s in matcher.scans])
    for r in rows:
        a = int(np.argmin(np.abs(t_ref - r["t_j"])))
        b = int(np.argmin(np.abs(t_ref - r["t_k"])))
        Pa, Pb = dr.poses(np.array([t_ref[a], t_ref[b]]))
        Ca, Cb = dr.covariance(float(t_ref[a])), dr.covariance(float(t_ref[b]))
        S = np.diag([1.0, 1.0, 1e-4]) if Ca is None or Cb is None else np.abs(Cb - Ca)
        reg = matcher.register(a, b, between(Pa, Pb), S)
        # back onto the loop's scan times (dead reckoning's motion: a fraction of a second)
        z = compose(
            compose(between(dr.poses(np.array([r["t_j"]]))[0], Pa), reg.z),
            between(Pb, dr.poses(np.array([r["t_k"]]))[0]),
        )
        r["dr_z"] = z.tolist()
        r["dr_accepted"] = bool(reg.accepted)
        r["dr_reason"] = reg.reason
        r["dr_time_offset_s"] = float(max(abs(t_ref[a] - r["t_j"]), abs(t_ref[b] - r["t_k"])))


def oracle_scores(
    run_dir: Path, rows: list[dict[str, Any]], ruler: Trajectory
) -> dict[str, dict[str, Any]]:
    """Step 6: the ATE of dead reckoning + heading + the ruler's relative poses at the pairs."""

    _, records, values, node_t, ds = load_run(run_dir)
    base = [r for r in records if family_of(r) in ("dr", "heading")]
    names = sorted(node_t, key=lambda n: node_t[n])
    t_nodes = np.array([node_t[n] for n in names])
    _, ruler_t, ruler_xy = ruler_of(ds)
    cov = np.diag([0.3**2, 0.3**2, np.radians(3.0) ** 2])
    out = {}
    for label, verdicts in (
        ("dr+heading", ()),
        ("accepted", ("accepted",)),
        ("accepted and the gate's rejects", ("accepted", "gate")),
        ("every pair tried", ("accepted", "gate", "registration")),
    ):
        extra = []
        for r in rows:
            if r["verdict"] not in verdicts:
                continue
            a = int(np.argmin(np.abs(t_nodes - r["t_j"])))
            b = int(np.argmin(np.abs(t_nodes - r["t_k"])))
            if a == b:
                continue
            z = between(*ruler.poses(t_nodes[[a, b]]))
            extra.append(
                FactorRecord.of(
                    FactorKind.BETWEEN_POSE,
                    [key_of(names[a]), key_of(names[b])],
                    z,
                    cov,
                    robust=Robust("cauchy", 1.0),
                    constraint="oracle-revisit",
                )
            )
        est = optimise(base + extra, values)
        out[label] = {
            "pairs": len(extra),
            **scores(node_trajectory(est, node_t), ruler_t, ruler_xy),
        }
    return out


def summary(rows: list[dict[str, Any]]) -> dict[str, Any]:
    """p50 / p90 / beyond 2 m of the position errors, the mean world error and the NEES median."""
    if not rows:
        return {"n": 0}
    err = np.array([r["err_m"] for r in rows])
    guess = np.array([r["guess_err_m"] for r in rows])
    nees = np.array([r["nees"] for r in rows if r["n_constrained"] == 3])
    return {
        "n": len(rows),
        "p50_m": float(np.percentile(err, 50)),
        "p90_m": float(np.percentile(err, 90)),
        "beyond_2m": float(np.mean(err > 2.0)),
        "mean_east_m": float(np.mean([r["err_east_m"] for r in rows])),
        "mean_north_m": float(np.mean([r["err_north_m"] for r in rows])),
        "guess_p50_m": float(np.percentile(guess, 50)),
        "guess_p90_m": float(np.percentile(guess, 90)),
        "nees_median_fully_constrained": float(np.median(nees)) if nees.size else float("nan"),
    }


def blocks(rows: list[dict[str, Any]], t0_s: float, block_s: float) -> list[dict[str, Any]]:
    """Step 4's pairs of time blocks of the accepted revisits: count, mean world error, scatter."""
    groups: dict[tuple[int, int], list[dict[str, Any]]] = defaultdict(list)
    for r in rows:
        if r["verdict"] == "accepted":
            a = int((r["t_j"] - t0_s) // block_s)
            b = int((r["t_k"] - t0_s) // block_s)
            groups[(a, b)].append(r)
    out = []
    for (a, b), rs in sorted(groups.items()):
        e = np.array([[r["err_east_m"], r["err_north_m"]] for r in rs])
        mean = e.mean(axis=0)
        out.append(
            {
                "block_j": a,
                "block_k": b,
                "n": len(rs),
                "mean_east_m": float(mean[0]),
                "mean_north_m": float(mean[1]),
                "scatter_m": float(np.sqrt(np.mean(np.sum((e - mean) ** 2, axis=1)))),
            }
        )
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    ap.add_argument("--source", default="marina", help="marina or a dataset directory")
    ap.add_argument("--set", action="append", default=[], metavar="SCOPE.FIELD=V")
    ap.add_argument("--run-out", type=Path, default=None, help="write the run directory here")
    ap.add_argument("--block-s", type=float, default=150.0, help="time blocks (s)")
    ap.add_argument("--dead-reckoning", action="store_true", help="step 5 too")
    ap.add_argument("--oracle", action="store_true", help="step 6 too")
    ap.add_argument("--batch", action="store_true", help="the run's final batch pass too")
    ap.add_argument("--out", type=Path, default=None, help="JSON of the scores and every pair")
    args = ap.parse_args(argv)
    try:
        settings = {"isam2.constraints": "lines,scans", **parse_settings(args.set)}
        out_dir = args.run_out or Path(tempfile.mkdtemp(prefix="loop_revisits_")) / "run"
        wall0 = time.perf_counter()
        result = run(
            args.source, "isam2", out_dir, progress=False, batch=args.batch, settings=settings
        )
    except (DataError, FileNotFoundError, ValueError) as exc:
        print(f"marina_loop_revisits: {exc}", file=sys.stderr)
        return 1
    wall = time.perf_counter() - wall0
    assert result.closed_loop is not None
    backend = result.closed_loop.backend
    if not isinstance(backend, LineIsam2) or backend.scans is None:
        print("marina_loop_revisits: the run has no scan constraints", file=sys.stderr)
        return 1
    ds = open_dataset(args.source)
    ruler = truth_trajectory(ds) if ds.truth is not None else gps_ahrs_trajectory(ds)
    rows = score_pairs(backend.scans.log.pairs, ruler)
    dr_rows: dict[str, Any] = {}
    if args.dead_reckoning:
        assert result.config is not None
        redo_with_dead_reckoning(ds, result.config.scans, rows)
        for r in rows:
            d, e_w = errors(np.asarray(r["dr_z"]), r["t_j"], r["t_k"], ruler)
            r["dr_err_m"] = float(np.hypot(d[0], d[1]))
            r["dr_err_north_m"] = float(e_w[1])
        for label, sel in (
            (
                "loop accepted, dead reckoning's registration accepted",
                lambda r: r["verdict"] == "accepted" and r["dr_accepted"],
            ),
            (
                "every tried pair, dead reckoning's registration accepted",
                lambda r: r["dr_accepted"],
            ),
        ):
            chosen = [r for r in rows if sel(r)]
            e = np.array([r["dr_err_m"] for r in chosen])
            e_loop = np.array([r["err_m"] for r in chosen])
            dr_rows[label] = {
                "n": len(chosen),
                "dr_p50_m": float(np.percentile(e, 50)) if e.size else float("nan"),
                "dr_p90_m": float(np.percentile(e, 90)) if e.size else float("nan"),
                "dr_beyond_2m": float(np.mean(e > 2.0)) if e.size else float("nan"),
                "loop_p50_m": float(np.percentile(e_loop, 50)) if e.size else float("nan"),
                "loop_p90_m": float(np.percentile(e_loop, 90)) if e.size else float("nan"),
                "loop_beyond_2m": float(np.mean(e_loop > 2.0)) if e.size else float("nan"),
            }
    t0 = float(ds.sonar_span_s[0])
    by_verdict = {
        v: summary([r for r in rows if r["verdict"] == v])
        for v in ("accepted", "gate", "registration")
    }
    bad = sorted(
        (r for r in rows if r["verdict"] == "accepted" and r["err_m"] > 2.0),
        key=lambda r: -r["err_m"],
    )
    m = result.metrics
    res = {
        "source": str(ds.root),
        "ruler": "truth" if ds.truth is not None else "gps+ahrs",
        "settings": {k: str(v) for k, v in settings.items()},
        "run_dir": str(out_dir),
        "wall_s": wall,
        "ate_sonar_mean_m": m.get("ate_sonar_mean_m"),
        "ate_sonar_mean_smoothed_m": m.get("ate_sonar_mean_smoothed_m"),
        "reasons": dict(Counter(r["reason"] or "accepted" for r in rows)),
        "by_verdict": by_verdict,
        "dead_reckoning_registrations": dr_rows,
        "oracle": oracle_scores(out_dir, rows, ruler) if args.oracle else {},
        "blocks": blocks(rows, t0, args.block_s),
        "accepted_beyond_2m": bad,
        "rows": rows,
    }
    print(
        f"{res['source']} ({res['ruler']}): {len(rows)} revisits tried, {wall:.0f} s; "
        f"online {res['ate_sonar_mean_m']}, smoothed {res['ate_sonar_mean_smoothed_m']}"
    )
    print(
        "| revisits | n | p50 / p90 / beyond 2 m | mean error (E, N) | graph's guess p50 / p90 |"
        " NEES median (3 dof) |"
    )
    print("|---|---|---|---|---|---|")
    for v, s in by_verdict.items():
        if s["n"]:
            print(
                f"| {v} | {s['n']} | {s['p50_m']:.2f} / {s['p90_m']:.2f} / {s['beyond_2m']:.0%} |"
                f" ({s['mean_east_m']:+.2f}, {s['mean_north_m']:+.2f}) |"
                f" {s['guess_p50_m']:.2f} / {s['guess_p90_m']:.2f} |"
                f" {s['nees_median_fully_constrained']:.1f} |"
            )
    for label, q in dr_rows.items():
        print(f"{label}: {q}")
    for label, o in res["oracle"].items():
        print(
            f"the ruler's relative poses at the pairs, {label} ({o['pairs']}): "
            f"{o['mean_m']:.2f} / {o['max_m']:.2f} m, aligned {o['aligned_mean_m']:.2f}"
        )
    print(f"accepted, by {args.block_s:g} s blocks (j, k): n, mean error (E, N), scatter")
    for b in res["blocks"]:
        print(
            f"  ({b['block_j']:2d}, {b['block_k']:2d}) n {b['n']:2d}"
            f"  ({b['mean_east_m']:+.2f}, {b['mean_north_m']:+.2f})  {b['scatter_m']:.2f}"
        )
    write_result(res, args.out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
