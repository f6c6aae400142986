"""Speed of the GTSAM back end in closed loop on one core.

The whole marina (the closed-loop extractor settings of
:func:`slam.run.run.default_extractor_config`, :class:`slam.backends.isam2.graph.LineIsam2` with its defaults,
its smoothed trajectory as the extractor's pose source): the real-time factor of the whole
closed loop (data span / wall time, extractor included; required >= 100x), the split between
extractor and back end, and per iSAM2 update (one per vote with lines, and the pending odometry
and heading factors at most every ``update_period_s``): p50, p99 and max wall time, with the
time spent in marginals (association candidates and the newest pose only) and in the
association. Then, outside the timed loop, the final smoothed trajectory with its marginal
covariances and an optional batch Levenberg-Marquardt pass. ATE (Mallios protocol) of the
online and smoothed trajectories and of dead reckoning.

Without ``$SONARSLAM_DATA/marina`` a simulated harbour (600 s, seed 1, the same rule: the
extractor's defaults for raw beams) replaces it, and the output says so. The process is pinned to one CPU and the BLAS thread pools
to one thread before numpy loads.

Usage::

    .venv/bin/python benchmarks/isam2_speed.py --out out/isam2_speed.json [--batch]
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import json  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402
from typing import Any  # noqa: E402

import numpy as np  # noqa: E402
from common import pin_one_core  # noqa: E402

from features.extractor import ExtractorConfig  # noqa: E402

REALTIME_FACTOR_MIN = 100.0


def open_run(source: str) -> tuple[str, Any, ExtractorConfig]:
    """The marina, a dataset directory, or a simulated harbour when the marina is absent; with
    the closed-loop extractor settings of :func:`slam.run.run.default_extractor_config`."""
    from datasets.source import data_root, open_dataset
    from slam.run.run import default_extractor_config

    root = data_root()
    if source == "marina" and root is not None and (root / "marina").is_dir():
        ds = open_dataset("marina")
        return "marina", ds, default_extractor_config(ds)
    if source != "marina":
        ds = open_dataset(source)
        return str(source), ds, default_extractor_config(ds)
    from datasets.simulator import simulate

    out = Path(tempfile.mkdtemp(prefix="isam2_speed_"))
    label = "simulated harbour seed 1, 600 s: the marina was not found under $SONARSLAM_DATA"
    ds = open_dataset(simulate("harbour", 1, out))
    return label, ds, default_extractor_config(ds)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--source", default="marina", help="marina (default) or a dataset dir")
    parser.add_argument("--out", default="out/isam2_speed.json")
    parser.add_argument("--batch", action="store_true", help="also time a final batch LM")
    args = parser.parse_args(argv)
    cpu = pin_one_core()

    from slam.backends.isam2.graph import GraphConfig, isam2_backend_factory, pose_source_of
    from slam.eval.ate import ate_against_gps
    from slam.run.closed_loop import run_closed_loop
    from slam.run.sources import dead_reckoning_trajectory

    label, dataset, extractor_config = open_run(args.source)
    config = GraphConfig()
    res = run_closed_loop(
        dataset,
        isam2_backend_factory(dataset.config.sonar_mounting, config),
        extractor_config,
        pose_source_of=pose_source_of,
        progress=False,
    )
    be = res.backend
    t0, t1 = res.trajectory.span_s
    data_s = t1 - t0
    log = np.array([u[1] for u in be.update_log])
    report: dict[str, Any] = {
        "source": label,
        "cpu": cpu,
        "config": {k: v for k, v in config.__dict__.items() if k != "association"},
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
        "association_s": be.timing_s["association"],
        "pose_nodes": be.n_nodes,
        "landmarks": len(be.landmarks),
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
        f"{be.timing_s['association']:.1f} s; {be.n_nodes} poses, {len(be.landmarks)} landmarks"
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
