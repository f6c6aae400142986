"""The floor a factor graph's own revisit pairs allow: the same graph with the ruler's relative
poses in place of its scan registrations. A benchmark only: the ruler is GPS + AHRS on the
marina (the simulator's truth on simulated data) and never an input of an estimator.

python benchmarks/marina_oracle_pairs.py --run DIR [--sigma-m 0.3] [--sigma-deg 1.0] \\
    [--out out/oracle_pairs.json]

DIR is an iSAM2 run directory with scan revisits (``sonarslam run marina --backend isam2
--batch --set isam2.constraints=scans --out DIR``; ``graph.json`` holds every factor and the
nodes' times). The benchmark

1. reads the graph (:meth:`sonarslam.slam.backends.isam2.graph_io.FactorRecord.to_gtsam`) and optimises it
   as it is with Levenberg-Marquardt from its saved values: the run's own batch estimate;
2. replaces the measurement of every ``scan-revisit`` factor by the ruler's relative pose of
   its two nodes (``between(ruler(t_i), ruler(t_j))``) with the stated covariance
   ``diag(sigma_m^2, sigma_m^2, sigma_deg^2)`` and no robust kernel, and optimises again: the
   *oracle* estimate, the best these pairs could give if every registration were as good as
   the ruler (within ``sigma``);
3. scores both against the ruler (ATE, sonar span and whole run, as published and SE(2)-aligned)
   and prints the gap.

The ruler's own error is in the oracle's pairs too, and the ATE is taken against the same ruler:
the floor is optimistic by what the ruler's error over a pair moves the estimate.
"""

from __future__ import annotations

import common  # noqa: F401  # first: one BLAS thread  # isort: skip
from common import write_result  # isort: skip

import argparse
import json
import sys
from pathlib import Path
from typing import Any

import gtsam
import numpy as np

from sonarslam.datasets.errors import DataError
from sonarslam.datasets.source import Dataset, open_dataset
from sonarslam.features.geometry import between
from sonarslam.slam.backends.isam2.graph_io import FactorKind, FactorRecord, key_of
from sonarslam.slam.eval.ate import ate_against_gps, ate_against_truth
from sonarslam.slam.eval.truth import truth_trajectory
from sonarslam.slam.io.trajectory import Trajectory
from sonarslam.slam.run.sources import gps_ahrs_trajectory


def _optimise(records: list[dict[str, Any]], values: gtsam.Values) -> gtsam.Values:
    graph = gtsam.NonlinearFactorGraph()
    for record in records:
        graph.add(FactorRecord.from_json(record).to_gtsam())
    params = gtsam.LevenbergMarquardtParams()
    params.setMaxIterations(100)
    return gtsam.LevenbergMarquardtOptimizer(graph, values, params).optimize()


def _trajectory(values: gtsam.Values, node_t: dict[str, float]) -> Trajectory:
    names = sorted(node_t, key=lambda n: node_t[n])
    poses = np.array(
        [[p.x(), p.y(), p.theta()] for p in (values.atPose2(key_of(n)) for n in names)]
    )
    return Trajectory(np.array([node_t[n] for n in names]), poses)


def _scores(ds: Dataset, tr: Trajectory) -> dict[str, float]:
    out: dict[str, float] = {}
    if ds.truth is not None:
        truth = truth_trajectory(ds)
        out["truth_mean_m"] = ate_against_truth(tr, truth).ate_mean_m
        out["truth_aligned_mean_m"] = ate_against_truth(tr, truth, align=True).ate_mean_m
    assert ds.gps is not None
    spans = {"sonar": ds.sonar_span_s, "whole": None}
    for name, span in spans.items():
        for aligned in (False, True):
            a = ate_against_gps(tr, ds.gps, span, align=aligned)
            tag = f"{name}{'_aligned' if aligned else ''}"
            out[f"{tag}_mean_m"] = a.ate_mean_m
            out[f"{tag}_max_m"] = a.ate_max_m
    return out


def oracle_records(
    records: list[dict[str, Any]],
    node_t: dict[str, float],
    ruler: Trajectory,
    sigma_m: float,
    sigma_deg: float,
) -> tuple[list[dict[str, Any]], int]:
    """The records with every scan-revisit measurement replaced by the ruler's (step 2), and
    how many were replaced."""
    cov = np.diag([sigma_m**2, sigma_m**2, np.deg2rad(sigma_deg) ** 2])
    out, n = [], 0
    for r in records:
        if r.get("constraint") == "scan-revisit":
            a, b = r["keys"]
            z = between(*ruler.poses(np.array([node_t[a], node_t[b]])))
            r = FactorRecord.of(
                FactorKind.BETWEEN_POSE,
                [key_of(a), key_of(b)],
                z,
                cov,
                constraint="scan-revisit-oracle",
            ).to_json()
            n += 1
        out.append(r)
    return out, n


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    ap.add_argument("--run", type=Path, required=True, help="an iSAM2 run directory")
    ap.add_argument("--sigma-m", type=float, default=0.3, help="oracle pair sigma per axis (m)")
    ap.add_argument("--sigma-deg", type=float, default=1.0, help="oracle pair yaw sigma (deg)")
    ap.add_argument("--out", type=Path, default=None, help="JSON of the scores")
    args = ap.parse_args(argv)
    path = args.run / "graph.json"
    try:
        doc = json.loads(path.read_text())
        ds = open_dataset(json.loads((args.run / "metrics.json").read_text())["source"])
    except (OSError, KeyError, ValueError, DataError) as exc:
        print(f"marina_oracle_pairs: {exc}", file=sys.stderr)
        return 1
    node_t = {k: float(v) for k, v in doc["meta"]["node_times_s"].items()}
    values = gtsam.Values()
    for name, item in doc["values"].items():
        v = np.asarray(item["value"], dtype=np.float64)
        values.insert(key_of(name), gtsam.Pose2(*v) if item["type"] == "Pose2" else v.reshape(-1))
    ruler = truth_trajectory(ds) if ds.truth is not None else gps_ahrs_trajectory(ds)
    records = doc["factors"]
    oracle, n = oracle_records(records, node_t, ruler, args.sigma_m, args.sigma_deg)
    if n == 0:
        print(f"marina_oracle_pairs: {path} has no scan-revisit factor", file=sys.stderr)
        return 1
    real = _scores(ds, _trajectory(_optimise(records, values), node_t))
    floor = _scores(ds, _trajectory(_optimise(oracle, values), node_t))
    result = {
        "run": str(args.run),
        "ruler": "truth" if ds.truth is not None else "gps+ahrs",
        "revisit_pairs": n,
        "sigma_m": args.sigma_m,
        "sigma_deg": args.sigma_deg,
        "batch": real,
        "oracle": floor,
        "gap": {k: real[k] - floor[k] for k in real},
    }
    print(
        f"{args.run}: {n} revisit pairs, oracle sigma {args.sigma_m} m / {args.sigma_deg} deg"
        f" ({result['ruler']} as the ruler)"
    )
    print("| estimate | sonar span mean / max (m) | aligned | whole run mean / max | aligned |")
    print("|---|---|---|---|---|")
    for name, s in (("the run's graph, batch", real), ("oracle pairs, batch", floor)):
        print(
            f"| {name} | {s['sonar_mean_m']:.2f} / {s['sonar_max_m']:.2f} | "
            f"{s['sonar_aligned_mean_m']:.2f} / {s['sonar_aligned_max_m']:.2f} | "
            f"{s['whole_mean_m']:.2f} / {s['whole_max_m']:.2f} | "
            f"{s['whole_aligned_mean_m']:.2f} / {s['whole_aligned_max_m']:.2f} |"
        )
    g = result["gap"]
    print(
        f"gap to the floor (sonar span mean): {g['sonar_mean_m']:+.2f} m, aligned"
        f" {g['sonar_aligned_mean_m']:+.2f} m"
    )
    write_result(result, args.out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
