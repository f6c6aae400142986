"""The EKF's AHRS heading NIS, per group of 40 updates, with the run's ATE: the marina or a
drawn world, with the yaw-rate source and back-end settings given (docs/research/consistency.md).

    .venv/bin/python benchmarks/heading_nis.py marina
    .venv/bin/python benchmarks/heading_nis.py marina --yaw-rate-source gyro
    .venv/bin/python benchmarks/heading_nis.py marina --set ekf.ahrs_period_s=10
    .venv/bin/python benchmarks/heading_nis.py 0 --cache /tmp/nees31/cache

Prints one JSON line: the heading NIS's median and the 10/50/90 % quantiles of its groups'
medians (chi2(1)'s median is 0.455), the line NIS's median, the ATE figures (against GPS on
the marina: a ruler only; against the truth too on a drawn world), the pose and heading NEES
against the truth on a drawn world, and the health monitor's verdict.
"""

from __future__ import annotations

import argparse
import json
import warnings
from dataclasses import replace
from typing import Any

import numpy as np

from sonarslam.datasets.source import Dataset, open_dataset
from sonarslam.slam.eval.consistency import nees_series
from sonarslam.slam.eval.truth import truth_trajectory
from sonarslam.slam.run.run import run_backend
from sonarslam.slam.run.sweep import calibrate_cached, simulate_cached

KEYS = (
    "ate_sonar_mean_m",
    "ate_sonar_max_m",
    "ate_sonar_aligned_mean_m",
    "ate_truth_mean_m",
    "ate_truth_aligned_mean_m",
    "health_ok",
    "health_flagged",
    "health_underconfident",
)


def dataset(name: str, cache: str) -> Dataset:
    """The marina (``SONARSLAM_DATA``) or drawn world ``name`` (a seed), calibrated GPS-free."""
    if name == "marina":
        return open_dataset("marina")
    folder = simulate_cached("drawn", int(name), None, cache)
    return open_dataset(folder, calibrate_cached(folder))


def measure(ds: Dataset, settings: dict[str, Any]) -> dict[str, Any]:
    """One EKF run's heading and line NIS, ATE, NEES and health (module docstring)."""
    run = run_backend(ds, "ekf", settings)
    assert run.closed_loop is not None
    backend = run.closed_loop.backend
    out: dict[str, Any] = {"yaw_rate_source": ds.config.yaw_rate_source, "settings": settings}
    h = np.asarray(getattr(backend, "heading_innovations", []), dtype=np.float64).reshape(-1, 3)
    if h.size:
        nis = h[:, 1] ** 2 / h[:, 2]
        medians = [float(np.median(nis[i : i + 40])) for i in range(0, nis.size, 40)]
        out["heading_updates"] = int(nis.size)
        out["heading_nis_median"] = float(np.median(nis))
        out["heading_nis_group_medians_q10_50_90"] = np.quantile(medians, [0.1, 0.5, 0.9]).tolist()
    if backend.map.innovations:
        out["line_nis_median"] = float(np.median(backend.map.nis()))
    out.update({k: run.metrics[k] for k in KEYS if k in run.metrics})
    if ds.truth is not None:
        truth = truth_trajectory(ds)
        for comp in ("pose", "heading"):
            out[f"nees_{comp}_mean"] = float(nees_series(run.trajectory, truth, comp).mean)
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("world", help="'marina' or a drawn world's seed")
    ap.add_argument("--yaw-rate-source", choices=("gyro", "heading"), default=None)
    ap.add_argument("--set", action="append", default=[], metavar="ekf.FIELD=V")
    ap.add_argument("--cache", default="out/sim-drawn")
    args = ap.parse_args()
    settings = {k: json.loads(v) for k, _, v in (s.partition("=") for s in args.set)}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        ds = dataset(args.world, args.cache)
        if args.yaw_rate_source is not None:
            ds = replace(ds, config=replace(ds.config, yaw_rate_source=args.yaw_rate_source))
        print(json.dumps({"world": args.world, **measure(ds, settings)}))


if __name__ == "__main__":
    main()
