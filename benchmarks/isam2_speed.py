"""Speed of the GTSAM back end in closed loop on one core.

The whole marina through the runner (:func:`sonarslam.slam.run.run.run_backend`: the extractor preset of
the beams, :class:`sonarslam.slam.backends.isam2.graph.LineIsam2` with its defaults, its smoothed
trajectory as the extractor's pose source): the real-time factor of the whole
closed loop (data span / wall time, extractor included; required >= 100x), the split between
extractor and back end, and per iSAM2 update (one per vote with lines, and the pending odometry
and heading factors at most every ``update_period_s``): p50, p99 and max wall time, with the
time spent in marginals (association candidates and the newest pose only) and in the
association. Then, outside the timed loop, the final smoothed trajectory with its marginal
covariances and an optional batch Levenberg-Marquardt pass. ATE (Mallios protocol) of the
online and smoothed trajectories and of dead reckoning.

Without ``$SONARSLAM_DATA/marina`` a simulated harbour (600 s, seed 1, the same rule: the
``default`` preset for raw beams) replaces it, and the output says so. The process is pinned to one CPU and the BLAS thread pools
to one thread before numpy loads.

Usage::

    .venv/bin/python benchmarks/isam2_speed.py --out out/isam2_speed.json [--batch]
    .venv/bin/python benchmarks/isam2_speed.py --set isam2.constraints=lines,scans  # + scans
"""

from __future__ import annotations

from common import open_run, pin_one_core  # first: one BLAS thread  # isort: skip

import argparse
import json
import sys
import time
from dataclasses import asdict
from pathlib import Path
from typing import Any

import numpy as np

from sonarslam.slam.backends.isam2.graph import LineIsam2
from sonarslam.slam.eval.ate import ate_against_gps
from sonarslam.slam.run.presets import parse_settings
from sonarslam.slam.run.run import run_backend
from sonarslam.slam.run.sources import dead_reckoning_trajectory

REALTIME_FACTOR_MIN = 100.0


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--source", default="marina", help="marina (default) or a dataset dir")
    parser.add_argument("--out", default="out/isam2_speed.json")
    parser.add_argument("--batch", action="store_true", help="also time a final batch LM")
    parser.add_argument(
        "--set", action="append", default=[], metavar="SCOPE.FIELD=V", help="a setting (run's)"
    )
    args = parser.parse_args(argv)
    cpu = pin_one_core()
    label, dataset = open_run(args.source)
    run = run_backend(dataset, "isam2", parse_settings(args.set))
    res = run.closed_loop
    assert res is not None and isinstance(res.backend, LineIsam2) and run.config is not None
    be = res.backend
    t0, t1 = res.trajectory.span_s
    data_s = t1 - t0
    log = np.array([u[1] for u in be.update_log])
    report: dict[str, Any] = {
        "source": label,
        "cpu": cpu,
        "extractor_preset": run.config.preset,
        "config": {k: v for k, v in asdict(be.config).items() if k != "association"},
        "data_s": data_s,
        "wall_s": res.wall_s,
        "extractor_s": res.extractor_s,
        "backend_s": res.backend_s,
        "realtime_factor": data_s / res.wall_s,
        "realtime_factor_min": REALTIME_FACTOR_MIN,
        "isam_updates": int(log.size),
        "isam_update_s_total": float(log.sum()),
        "isam_update_ms_p50": float(1e3 * np.percentile(log, 50)),
        "isam_update_ms_p99": float(1e3 * np.percentile(log, 99)),
        "isam_update_ms_max": float(1e3 * log.max()),
        "marginals_s": be.timing_s["marginals"],
        "scans_s": be.timing_s.get("scans", 0.0),
        "scan_matcher_s": res.scan_matcher_s,
        "settings": run.config.settings,
        "association_s": be.timing_s["association"],
        "pose_nodes": be.n_nodes,
        "landmarks": len(be.map),
        "stats": be.stats,
        "counts": res.counts,
    }
    a = time.perf_counter()
    smoothed = be.smoothed_trajectory(covariances=True)
    report["smoothed_with_covariances_s"] = time.perf_counter() - a
    if dataset.gps is not None:
        report["ate_online_m"] = ate_against_gps(res.trajectory, dataset.gps).ate_mean_m
        report["ate_smoothed_m"] = ate_against_gps(smoothed, dataset.gps).ate_mean_m
        dr = dead_reckoning_trajectory(dataset).clip(t0, t1)
        report["ate_dead_reckoning_m"] = ate_against_gps(dr, dataset.gps).ate_mean_m
    if args.batch:
        a = time.perf_counter()
        be.optimize_batch()
        report["batch_lm_s"] = time.perf_counter() - a
        if dataset.gps is not None:
            batch = be.smoothed_trajectory()
            report["ate_batch_m"] = ate_against_gps(batch, dataset.gps).ate_mean_m
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(report, indent=2) + "\n")
    print(
        f"{label}: {data_s:.0f} s of data in {res.wall_s:.1f} s ({report['realtime_factor']:.0f}x, "
        f"required >= {REALTIME_FACTOR_MIN:.0f}x); extractor {res.extractor_s:.1f} s, back end "
        f"{res.backend_s:.1f} s; {log.size} iSAM2 updates, p50 {report['isam_update_ms_p50']:.1f} "
        f"ms, p99 {report['isam_update_ms_p99']:.1f} ms, max {report['isam_update_ms_max']:.0f} ms, "
        f"total {log.sum():.1f} s; marginals {be.timing_s['marginals']:.1f} s, association "
        f"{be.timing_s['association']:.1f} s; {be.n_nodes} poses, {len(be.map)} landmarks"
    )
    if "ate_online_m" in report:
        print(
            f"ATE online {report['ate_online_m']:.2f} m, smoothed {report['ate_smoothed_m']:.2f} m, "
            f"dead reckoning {report['ate_dead_reckoning_m']:.2f} m"
        )
    print(f"written {out}")
    return 0 if report["realtime_factor"] >= REALTIME_FACTOR_MIN else 1


if __name__ == "__main__":
    sys.exit(main())
