"""The sonar's direction of motion against dead reckoning's, GPS-free: the DVL/sonar crab.

Pairs of scans a few metres apart along dead reckoning are registered
(:func:`sonarslam.slam.eval.loops.odometry_pairs`, the product's registration) and the angle
from dead reckoning's translation to the sonar's is taken for each accepted pair. That angle
measures ``delta - e``: ``delta`` the turn the DVL's velocity needs to point where the vehicle
goes (a misalignment, or a lateral bias over the speed: the graph's ``D(0)``), ``e`` the error
of the configured sonar mounting yaw (the graph's ``C(0)`` yaw minus its prior). A constant
heading error cancels in both relative poses, so nothing here is GPS or the AHRS's absolute
heading: only the DVL's direction in the body against the sonar's.

Reported per dataset: the mean angle with a standard error from batch means over blocks of
consecutive pairs (neighbouring pairs share scans), the median, the inverse-variance weighted
mean (the registration's covariance across the translation), the scale (sonar over DVL
lengths), and the mean in bins of heading, speed, turn during the pair and time. On a simulated
world with ``truth.json`` each pair also gets what the angle should be
(:func:`sonarslam.slam.model.calibration.scan_prediction` of the true relative motion with the
true mounting and range scale), split into the DVL's part (dead reckoning to the true motion:
the crab) and the mounting's (the true motion to the prediction, ``-e``), and the registration's
own error (measured minus predicted): the truth as a ruler of the method.

    .venv/bin/python benchmarks/sonar_dvl_direction.py marina /tmp/nees31/cache/drawn_0_default \\
        --out docs/sonar-dvl-direction.json

A world folder's ``calibration.toml`` beside its ``sonarslam.toml`` is applied (as ``sweep
--calibrate`` does); ``--no-calibration`` leaves it out.
"""

from __future__ import annotations

import common  # noqa: F401  # first: one BLAS thread  # isort: skip
from common import write_result  # isort: skip

import argparse
import math
import time
from pathlib import Path
from typing import Any

import numpy as np

from sonarslam.datasets.source import Dataset, open_dataset
from sonarslam.features.geometry import between, wrap_angle
from sonarslam.features.scans.config import ScanConfig
from sonarslam.features.scans.scan import ScanBuilder
from sonarslam.slam.eval.loops import OdometryPair, odometry_pairs
from sonarslam.slam.eval.truth import true_sonar, truth_trajectory
from sonarslam.slam.model.calibration import scan_prediction
from sonarslam.slam.run.run import ODOMETRY_STEP_SHARE
from sonarslam.slam.run.sources import dead_reckoning_trajectory

#: Pairs per turn of the head by default (neighbouring pairs then share scans).
PAIRS_PER_TURN = 3
#: Consecutive pairs per block of the batch-means standard error: a pair's scans are at most five
#: turns of the head apart, so pairs further apart than a block (about seven turns) share none.
BLOCK = 20


def _angle(a: np.ndarray, b: np.ndarray) -> float:
    """The angle from translation ``a[:2]`` to ``b[:2]`` (rad, wrapped)."""
    return float(wrap_angle(math.atan2(b[1], b[0]) - math.atan2(a[1], a[0])))


def summary(values_deg: np.ndarray, sd_deg: np.ndarray | None = None) -> dict[str, Any]:
    """Mean, batch-means standard error, median and (with ``sd_deg``) the weighted mean of
    angles (deg) in pair order."""
    v = np.asarray(values_deg, dtype=np.float64)
    out: dict[str, Any] = {"n": int(v.size)}
    if v.size == 0:
        return out
    out["mean_deg"] = float(np.mean(v))
    out["median_deg"] = float(np.median(v))
    out["sd_deg"] = float(np.std(v, ddof=1)) if v.size > 1 else math.nan
    n_blocks = v.size // BLOCK
    if n_blocks >= 4:
        means = v[: n_blocks * BLOCK].reshape(n_blocks, BLOCK).mean(axis=1)
        out["se_deg"] = float(np.std(means, ddof=1) / math.sqrt(n_blocks))
    elif v.size > 1:
        out["se_deg"] = float(np.std(v, ddof=1) / math.sqrt(v.size))
    if sd_deg is not None:
        w = 1.0 / np.maximum(np.asarray(sd_deg), 0.1) ** 2
        out["weighted_mean_deg"] = float(np.sum(w * v) / np.sum(w))
    return out


def _bins(values: np.ndarray, key: np.ndarray, edges: list[float], label: str) -> list[dict]:
    rows = []
    for lo, hi in zip(edges[:-1], edges[1:], strict=True):
        inside = (key >= lo) & (key < hi)
        row = {label: [round(lo, 3), round(hi, 3)]}
        row.update(summary(values[inside]))
        rows.append(row)
    return rows


def measure(
    source: str,
    n_pairs: int | None,
    step_m: float | None,
    calibration: bool,
    with_pairs: bool = False,
) -> dict:
    """The pairs of one dataset and their statistics."""
    folder = Path(source)
    cal = folder / "calibration.toml"
    override = cal if calibration and cal.is_file() else None
    ds: Dataset = open_dataset(source, config_override=override)
    dr = dead_reckoning_trajectory(ds)
    config = ScanConfig()
    head = ds.config.sonar
    range_m = head.n_bins * head.bin_size_m
    step = step_m if step_m is not None else min(max(ODOMETRY_STEP_SHARE * range_m, 1.0), 5.0)
    n_turn = ScanBuilder(config, head, ds.config.sonar_mounting, dr).n_beams
    turn_s = float(np.median(np.diff(ds.beams.t_s))) * n_turn
    span = ds.sonar_span_s
    assert span is not None
    n = n_pairs if n_pairs is not None else int(PAIRS_PER_TURN * (span[1] - span[0]) / turn_s)
    t0 = time.process_time()
    pairs: list[OdometryPair] = odometry_pairs(ds, dr, step, n, config)
    cpu_s = time.process_time() - t0
    done = [p for p in pairs if p.sonar is not None]
    angle = np.rad2deg([p.angle_rad for p in done])
    angle_sd = np.rad2deg([p.angle_sd_rad for p in done])
    t_rel = np.array([p.t0_s for p in done]) - span[0]
    dt = np.array([p.t1_s - p.t0_s for p in done])
    speed = np.array([math.hypot(*p.dead_reckoning[:2]) for p in done]) / dt
    turn = np.rad2deg(np.abs([p.dead_reckoning[2] for p in done]))
    heading = (
        np.rad2deg([float(wrap_angle(dr.poses(np.array([p.t0_s]))[0, 2])) for p in done]) % 360.0
    )
    # a gross outlier (a wrong registration that passed the matcher's tests) beyond 4 robust
    # sigmas of the median is reported and left out of the statistics
    med = float(np.median(angle)) if angle.size else 0.0
    mad = 1.4826 * float(np.median(np.abs(angle - med))) if angle.size else 0.0
    keep = np.abs(angle - med) <= 4.0 * max(mad, 0.1)
    a, s = angle[keep], angle_sd[keep]
    result: dict[str, Any] = {
        "source": source,
        "calibration_toml": str(override) if override else None,
        "step_m": step,
        "turn_s": turn_s,
        "pairs_registered": len(pairs),
        "pairs_accepted": len(done),
        "outliers_left_out": int((~keep).sum()),
        "cpu_s": round(cpu_s, 1),
        "angle": summary(a, s),
        "angle_all": summary(angle, angle_sd),
        "scale_median": float(np.median([p.scale for p in done])) if done else math.nan,
        "by_heading": _bins(a, heading[keep], [0, 45, 90, 135, 180, 225, 270, 315, 360], "deg"),
        "by_speed": _bins(
            a,
            speed[keep],
            list(np.quantile(speed[keep], [0, 1 / 3, 2 / 3, 1.0]) + [0, 0, 0, 1e-9]),
            "mps",
        ),
        "by_turn": _bins(a, turn[keep], [0.0, 5.0, 20.0, 360.0], "deg"),
        "by_time": _bins(
            a, t_rel[keep], list(np.linspace(0.0, span[1] - span[0], 5) + [0, 0, 0, 0, 1e-9]), "s"
        ),
        "harmonic_fit_deg": _harmonic(a, heading[keep]),
    }
    if with_pairs:
        result["pairs"] = [
            {
                "t0_s": round(p.t0_s - span[0], 2),
                "t1_s": round(p.t1_s - span[0], 2),
                "angle_deg": round(float(np.rad2deg(p.angle_rad)), 3),
                "angle_sd_deg": round(float(np.rad2deg(p.angle_sd_rad)), 3),
                "scale": round(p.scale, 4),
            }
            for p in done
        ]
    if ds.truth is not None:
        result["truth"] = _truth(ds, done, keep)
    return result


def _harmonic(angle_deg: np.ndarray, heading_deg: np.ndarray) -> dict[str, float]:
    """Least squares ``angle = c0 + B sin(heading) + C cos(heading)`` (deg)."""
    if angle_deg.size < 6:
        return {}
    h = np.deg2rad(heading_deg)
    A = np.column_stack([np.ones_like(h), np.sin(h), np.cos(h)])
    coef, *_ = np.linalg.lstsq(A, angle_deg, rcond=None)
    return {"c0": float(coef[0]), "B_sin": float(coef[1]), "C_cos": float(coef[2])}


def _truth(ds: Dataset, done: list[OdometryPair], keep: np.ndarray) -> dict[str, Any]:
    """Each pair's angle as the truth predicts it, split into the DVL's part and the mounting's
    (module docstring)."""
    truth = truth_trajectory(ds)
    bTs, range_scale = true_sonar(ds)
    told = ds.config.sonar_mounting.as_pose()
    crab, mount, expected = [], [], []
    for p in done:
        w = truth.poses(np.array([p.t0_s, p.t1_s]))
        iTj = between(w[0], w[1])
        h, *_ = scan_prediction(iTj, bTs, range_scale, told)
        crab.append(_angle(p.dead_reckoning, iTj))
        mount.append(_angle(iTj, h))
        expected.append(_angle(p.dead_reckoning, h))
    crab_d, mount_d, exp_d = (np.rad2deg(np.asarray(x))[keep] for x in (crab, mount, expected))
    measured = np.rad2deg([p.angle_rad for p in done])[keep]
    errors = ds.truth.get("errors", {}) if ds.truth else {}
    return {
        "sonar_yaw_error_deg": float(np.rad2deg(wrap_angle(bTs[2] - told[2]))),
        "dvl_bias_mps": errors.get("dvl_bias_mps"),
        "dvl_part_deg": summary(crab_d),
        "mounting_part_deg": summary(mount_d),
        "expected_deg": summary(exp_d),
        "registration_error_deg": summary(measured - exp_d),
    }


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("sources", nargs="+", help="marina or dataset folders (simulated worlds)")
    ap.add_argument(
        "--pairs",
        type=int,
        default=None,
        help="pairs per dataset (default: three per turn of the head)",
    )
    ap.add_argument(
        "--step-m",
        type=float,
        default=None,
        help="distance along DR (default: as the run's odometry check)",
    )
    ap.add_argument(
        "--no-calibration", action="store_true", help="leave out a world's calibration.toml"
    )
    ap.add_argument("--with-pairs", action="store_true", help="every pair in the JSON too")
    ap.add_argument("--out", type=Path, default=None)
    args = ap.parse_args(argv)
    rows = []
    for src in args.sources:
        r = measure(src, args.pairs, args.step_m, not args.no_calibration, args.with_pairs)
        a = r["angle"]
        line = (
            f"{src}: {r['pairs_accepted']}/{r['pairs_registered']} pairs, angle DR->sonar"
            f" {a.get('mean_deg', math.nan):+.2f} +- {a.get('se_deg', math.nan):.2f} deg"
            f" (median {a.get('median_deg', math.nan):+.2f}, weighted"
            f" {a.get('weighted_mean_deg', math.nan):+.2f}, sd {a.get('sd_deg', math.nan):.2f});"
            f" scale {r['scale_median']:.4f}; {r['cpu_s']} s CPU"
        )
        if "truth" in r:
            tr = r["truth"]
            line += (
                f"\n   truth: expected {tr['expected_deg']['mean_deg']:+.2f} (DVL part"
                f" {tr['dvl_part_deg']['mean_deg']:+.2f}, mounting part"
                f" {tr['mounting_part_deg']['mean_deg']:+.2f}; sonar yaw error"
                f" {tr['sonar_yaw_error_deg']:+.3f}); registration error"
                f" {tr['registration_error_deg']['mean_deg']:+.2f} +-"
                f" {tr['registration_error_deg'].get('se_deg', math.nan):.2f}"
            )
        print(line, flush=True)
        rows.append(r)
    write_result({"benchmark": "sonar_dvl_direction", "datasets": rows}, args.out)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
