"""How much of the marina's ATE is the absolute heading: a measurement, not a calibration.

python benchmarks/marina_heading.py [--closed-loop] [--out FILE.json]

Every position estimate here integrates the DVL velocity along the AHRS heading, so a constant
heading error ``e`` turns the whole run about its start and costs about ``e * distance`` of ATE.
Nothing GPS-free observes that constant (line landmarks, DVL and gyro are blind to a rotation of
the whole map and run), so it is set by the AHRS mounting (``[mounting.ahrs] yaw_deg``, found
GPS-free from the DVL's own compass). This script measures, on the real marina:

1. the dead-reckoning ATE against GPS as the AHRS mounting is turned by ``d`` degrees (the
   GPS-best ``d`` is a *diagnostic* of the heading error: it uses the ground truth);
2. GPS-free: the two compasses on board (the MTi and the DVL's) disagree by an amount that
   depends on the heading, so at least one of them is deflected by the vehicle (compass
   deviation) and neither is a reference at the degree level;
3. with GPS, over a calibration leg: the rotation that best fits the first ``T`` seconds of
   dead reckoning to GPS, for several ``T`` (what a surface calibration leg would give);
4. with ``--closed-loop``: the EKF and iSAM2 closed loops (no GPS in the loop) with the AHRS
   mounting as calibrated and turned by the GPS-best ``d``.
"""

from __future__ import annotations

import argparse
import json
import math
from dataclasses import replace
from pathlib import Path

import numpy as np

from sonarslam.datasets.errors import DataError
from sonarslam.datasets.source import Dataset, open_dataset
from sonarslam.slam.eval.ate import ate_against_gps
from sonarslam.slam.run.run import run_backend
from sonarslam.slam.run.sources import dead_reckoning_trajectory, start_pose


def turned(dataset: Dataset, d_deg: float) -> Dataset:
    """The dataset with its AHRS mounting yaw turned by ``d_deg`` (body yaw turns by -d)."""
    m = dataset.config.ahrs_mounting
    mount = replace(
        m, yaw_rad=m.yaw_rad + math.radians(d_deg), source=f"{m.source}, {d_deg:+g} deg"
    )
    return replace(dataset, config=replace(dataset.config, ahrs_mounting=mount))


def dr_ate_against_turn(dataset: Dataset, d_deg: np.ndarray) -> list[dict[str, float]]:
    assert dataset.gps is not None
    rows = []
    for d in d_deg:
        a = ate_against_gps(dead_reckoning_trajectory(turned(dataset, float(d))), dataset.gps)
        rows.append({"d_deg": float(d), "ate_mean_m": a.ate_mean_m, "ate_max_m": a.ate_max_m})
    return rows


def compass_disagreement(dataset: Dataset, bin_deg: float = 30.0) -> list[dict[str, float]]:
    """Circular mean of (DVL compass - MTi yaw) in bins of MTi yaw (GPS-free)."""
    dvl, att = dataset.dvl, dataset.attitude
    yaw_mti = np.interp(dvl.t, att.t, np.unwrap(att.yaw_rad))
    diff = np.exp(1j * (dvl.heading_rad - yaw_mti))
    h = np.degrees(yaw_mti) % 360.0
    rows = []
    for lo in np.arange(0.0, 360.0, bin_deg):
        m = (h >= lo) & (h < lo + bin_deg)
        if m.sum() >= 20:
            rows.append(
                {
                    "mti_yaw_deg": float(lo + bin_deg / 2),
                    "n": int(m.sum()),
                    "dvl_minus_mti_deg": float(np.degrees(np.angle(diff[m].mean()))),
                }
            )
    return rows


def leg_rotation(dataset: Dataset, legs_s: list[float]) -> list[dict[str, float]]:
    """Rotation (deg, CCW) about the start that best maps dead reckoning onto GPS over a leg."""
    gps = dataset.gps
    assert gps is not None
    dr = dead_reckoning_trajectory(dataset)
    t0 = start_pose(dataset)[0]
    rows = []
    for T in legs_s:
        m = (gps.t >= t0) & (gps.t <= t0 + T)
        u = dr.poses(gps.t[m])[:, :2]
        u = u - u[0]
        v = gps.en_m[m] - gps.en_m[m][0]
        ang = math.atan2(float(np.sum(u[:, 0] * v[:, 1] - u[:, 1] * v[:, 0])), float(np.sum(u * v)))
        path = float(np.hypot(*np.diff(gps.en_m[m], axis=0).T).sum())
        rows.append({"leg_s": T, "gps_path_m": path, "rotation_deg": math.degrees(ang)})
    return rows


def closed_loops(dataset: Dataset, d_deg: float) -> list[dict[str, float]]:
    assert dataset.gps is not None
    rows = []
    for d in (0.0, d_deg):
        ds = turned(dataset, d)
        ekf = run_backend(ds, "ekf")
        gr = run_backend(ds, "isam2")
        for name, tr in (
            ("dr", dead_reckoning_trajectory(ds)),
            ("ekf", ekf.trajectory),
            ("isam2", gr.trajectory),
            ("isam2_smoothed", gr.trajectories["smoothed"]),
        ):
            a = ate_against_gps(tr, dataset.gps)
            rows.append(
                {"d_deg": d, "estimate": name, "ate_mean_m": a.ate_mean_m, "ate_max_m": a.ate_max_m}
            )
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--source", default="marina")
    parser.add_argument(
        "--closed-loop", action="store_true", help="also run EKF and iSAM2 (~2 min)"
    )
    parser.add_argument("--out", default=None, help="results JSON")
    args = parser.parse_args()
    try:
        ds = open_dataset(args.source)
    except DataError as exc:
        print(f"skipped: {exc}")  # the measurement is of the real marina; nothing to fake
        return
    result: dict[str, object] = {}

    grid = np.arange(-8.0, 12.01, 0.5)
    dr = dr_ate_against_turn(ds, grid)
    best = min(dr, key=lambda r: r["ate_mean_m"])
    result["dr_ate_against_turn"] = dr
    print("1. dead reckoning ATE against GPS as the AHRS mounting turns by d (GPS diagnostic)")
    for r in dr:
        if r["d_deg"] % 2 == 0 or r is best:
            print(
                f"   d {r['d_deg']:+5.1f} deg: mean {r['ate_mean_m']:6.2f} m, max {r['ate_max_m']:6.2f} m"
            )
    at = {r["d_deg"]: r["ate_mean_m"] for r in dr}
    print(
        f"   GPS-best d = {best['d_deg']:+.1f} deg; one degree either side of it costs"
        f" {0.5 * (at[best['d_deg'] - 1.0] + at[best['d_deg'] + 1.0]) - best['ate_mean_m']:.2f} m"
        " of mean ATE on average"
    )

    comp = compass_disagreement(ds)
    result["compass_disagreement"] = comp
    spread = [r["dvl_minus_mti_deg"] for r in comp]
    print("2. DVL compass minus MTi yaw by MTi yaw (GPS-free)")
    print("   " + ", ".join(f"{r['mti_yaw_deg']:.0f}: {r['dvl_minus_mti_deg']:.1f}" for r in comp))
    print(f"   range {min(spread):.1f} to {max(spread):.1f} deg: a heading-dependent deviation")

    legs = leg_rotation(ds, [300.0, 600.0, 900.0, 1200.0, 3400.0])
    result["leg_rotation"] = legs
    print(
        "3. rotation about the start fitting dead reckoning to GPS over a leg (uses GPS;"
        " a rotation of -x deg is d = +x)"
    )
    for r in legs:
        print(
            f"   first {r['leg_s']:6.0f} s ({r['gps_path_m']:5.0f} m of GPS path): {r['rotation_deg']:+.2f} deg"
        )

    if args.closed_loop:
        rows = closed_loops(ds, best["d_deg"])
        result["closed_loops"] = rows
        print(
            "4. closed loops (no GPS in the loop) with the AHRS mounting as calibrated and turned"
        )
        for r in rows:
            print(
                f"   d {r['d_deg']:+4.1f} {r['estimate']:15s} mean {r['ate_mean_m']:6.2f} m, max {r['ate_max_m']:6.2f} m"
            )
    if args.out:
        Path(args.out).write_text(json.dumps(result, indent=1) + "\n")


if __name__ == "__main__":
    main()
