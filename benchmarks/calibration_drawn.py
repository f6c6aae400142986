"""The sonar's calibration as state on drawn worlds: its estimates against the simulator's truth,
and what it does to the ATE.

python benchmarks/calibration_drawn.py RUN_DIR... [--against BASE_DIR...] [--out FILE.json]

Each ``RUN_DIR`` is a ``sonarslam run`` of a drawn world (``sonarslam simulate drawn --seed N``)
with the calibration estimated (``--set isam2.estimate_sonar_mount=true --set
isam2.range_scale_sigma=0.04``, or the EKF's ``ekf.`` settings of the same names); its ``metrics.json`` names the dataset, whose ``truth.json`` holds
the true mounting (``mountings.sonar``; ``sonarslam.toml`` has it without the drawn offsets) and
range scale (``errors.sonar_range_scale``). Per run: each estimate's error in sigmas of its own
marginal; the AHRS heading error's track (``heading_error.csv``) against the true one (the share
of nodes inside its 2-sigma band); the ATE against the truth (online and smoothed, as it is and
aligned; a filter's run has no smoothed estimate, shown as ``-``). ``--against`` gives the same worlds' runs without the calibration (same order), whose
ATE stands beside. Truth is only a ruler here: nothing is fed back.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any

import numpy as np

from sonarslam.datasets.source import open_dataset
from sonarslam.slam.eval.truth import (
    CALIBRATION_SD_KEYS,
    calibration_sigmas,
    true_calibration,
    truth_heading_error,
)
from sonarslam.slam.io.states import HEADING_ERROR_FILE, read_heading_error

#: The ATE keys compared (against the truth).
ATE_KEYS = (
    "ate_truth_mean_m",
    "ate_truth_smoothed_mean_m",
    "ate_truth_aligned_mean_m",
    "ate_truth_aligned_smoothed_mean_m",
)


#: This table's names of the sonar's calibration estimates -> their ``metrics.json`` keys.
NAMES = {
    "x_m": "state_sonar_x_m",
    "y_m": "state_sonar_y_m",
    "yaw_deg": "state_sonar_yaw_deg",
    "range_scale": "state_sonar_range_scale",
}


def calibration_errors(run_dir: Path) -> dict[str, Any]:
    """One run's estimates, their sd and their error in sigmas against the truth."""
    m = json.loads((run_dir / "metrics.json").read_text())
    dataset = open_dataset(m["source"])
    truth = dataset.truth
    assert truth is not None, f"{m['source']}: no truth.json"
    true_values = true_calibration(dataset, dataset.nav_span_s[1])
    out: dict[str, Any] = {"run": str(run_dir), "seed": truth["seed"]}
    for name, key in NAMES.items():
        if key in m:
            out[name] = {
                "estimate": m[key],
                "sd": m[CALIBRATION_SD_KEYS[key]],
                "truth": true_values[key],
                "z": calibration_sigmas(m, true_values, key),
            }
    track = run_dir / HEADING_ERROR_FILE
    true_b = truth_heading_error(dataset)
    if track.exists() and true_b is not None:
        t, b, sd = read_heading_error(track)
        at = np.interp(t, *true_b)
        out["heading_inside_2sigma"] = float(np.mean(np.abs(at - b) <= 2.0 * sd))
    out["ate"] = {k: m.get(k) for k in ATE_KEYS}
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("runs", nargs="+", type=Path)
    parser.add_argument("--against", nargs="*", type=Path, default=[])
    parser.add_argument("--out", type=Path)
    args = parser.parse_args()
    if args.against and len(args.against) != len(args.runs):
        parser.error("--against takes one run directory per RUN_DIR, in the same order")
    rows = [calibration_errors(r) for r in args.runs]
    for row, base in zip(rows, args.against, strict=False):
        mb = json.loads((base / "metrics.json").read_text())
        row["ate_without"] = {k: mb.get(k) for k in ATE_KEYS}
    names = tuple(NAMES)
    print(
        "| seed | " + " | ".join(f"{n} est ± sd (truth) z" for n in names) + " | b in 2σ |"
        " ATE online / smoothed / aligned online / aligned smoothed (without → with) |"
    )
    print("|---" * (len(names) + 3) + "|")
    for r in rows:
        cells = [
            f"{r[n]['estimate']:.3f} ± {r[n]['sd']:.3f} ({r[n]['truth']:.3f}) {r[n]['z']:+.1f}"
            if n in r
            else "-"
            for n in names
        ]
        h = r.get("heading_inside_2sigma")
        a = r["ate"]
        w = r.get("ate_without", {})
        ate = " / ".join(
            f"{w.get(k, float('nan')) or float('nan'):.2f} → {a[k]:.2f}"
            if a[k] is not None
            else "-"
            for k in (
                "ate_truth_mean_m",
                "ate_truth_smoothed_mean_m",
                "ate_truth_aligned_mean_m",
                "ate_truth_aligned_smoothed_mean_m",
            )
        )
        print(
            f"| {r['seed']} | "
            + " | ".join(cells)
            + f" | {'-' if h is None else f'{h:.2f}'} | {ate} |"
        )
    summary: dict[str, Any] = {}
    for n in names:
        z = [abs(r[n]["z"]) for r in rows if n in r]
        if z:
            summary[f"{n}_within_2sigma"] = float(np.mean(np.array(z) <= 2.0))
    summary["all_within_2sigma"] = float(
        np.mean([all(abs(r[n]["z"]) <= 2.0 for n in names if n in r) for r in rows])
    )
    for k in ATE_KEYS:
        if any(r["ate"][k] is None for r in rows):
            continue  # a filter's runs: no smoothed estimate
        summary[f"mean_{k}"] = float(np.mean([r["ate"][k] for r in rows]))
        if args.against:
            summary[f"mean_{k}_without"] = float(np.mean([r["ate_without"][k] for r in rows]))
    print(json.dumps(summary, indent=1))
    if args.out:
        args.out.write_text(json.dumps({"rows": rows, "summary": summary}, indent=1) + "\n")


if __name__ == "__main__":
    main()
