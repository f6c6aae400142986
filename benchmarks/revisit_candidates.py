"""How many revisits a run's geometry allows, against how many the loop tried: for every scan,
the older scans (at least ``--min-gap-s`` before it) whose reference positions lie within
``--radius-m`` of its own, by the ruler (the simulator's truth, or GPS + AHRS on the marina: a
benchmark only, never an input) and by dead reckoning. A benchmark only.

python benchmarks/revisit_candidates.py [--source marina|DIR] [--loop F.json ...] \\
    [--radius-m 10] [--min-gap-s 60] [--out out/revisit_candidates.json]

Prints, per trajectory, the scans with at least one such older scan and the sums over scans of
``min(n, 1)``, ``min(n, 2)``, ``min(n, 4)`` and ``n``: the revisits one, two or four per scan can
take when the older scans are taken with no spacing between them. ``--loop`` takes
``benchmarks/marina_loop_revisits.py --out`` files of runs on the same source and adds how many
revisits each tried, per scan (matched by time) and in all, with the spacing of the older scans
each scan's revisits took.
"""

from __future__ import annotations

import common  # noqa: F401  # first: one BLAS thread  # isort: skip
from common import write_result  # isort: skip

import argparse
import json
import sys
from collections import Counter, defaultdict
from pathlib import Path
from typing import Any

import numpy as np
from marina_registration import build_scans

from sonarslam.datasets.errors import DataError
from sonarslam.datasets.source import open_dataset
from sonarslam.features.scans import ScanConfig
from sonarslam.slam.eval.truth import truth_trajectory
from sonarslam.slam.run.sources import dead_reckoning_trajectory, gps_ahrs_trajectory


def neighbours(xy: np.ndarray, t_s: np.ndarray, radius_m: float, min_gap_s: float) -> np.ndarray:
    """Per scan ``k``, the count of older scans ``j`` with ``t_k - t_j >= min_gap_s`` and
    ``|xy_k - xy_j| <= radius_m``; shape (n,)."""
    out = np.zeros(len(t_s), dtype=int)
    for k in range(len(t_s)):
        d = np.hypot(*(xy[:k] - xy[k]).T)
        out[k] = int(np.sum((t_s[k] - t_s[:k] >= min_gap_s) & (d <= radius_m)))
    return out


def allowed(n: np.ndarray) -> dict[str, int]:
    """Scans with any older neighbour, and the sums of ``min(n, m)``."""
    return {
        "scans_with_any": int(np.sum(n > 0)),
        "sum_min_1": int(np.minimum(n, 1).sum()),
        "sum_min_2": int(np.minimum(n, 2).sum()),
        "sum_min_4": int(np.minimum(n, 4).sum()),
        "sum_all": int(n.sum()),
    }


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    ap.add_argument("--source", default="marina", help="marina or a dataset directory")
    ap.add_argument("--loop", type=Path, action="append", default=[], help="loop revisits JSON")
    ap.add_argument("--radius-m", type=float, default=10.0)
    ap.add_argument("--min-gap-s", type=float, default=60.0)
    ap.add_argument("--out", type=Path, default=None)
    args = ap.parse_args(argv)
    try:
        ds = open_dataset(args.source)
    except (DataError, FileNotFoundError, ValueError) as exc:
        print(f"revisit_candidates: {exc}", file=sys.stderr)
        return 1
    dr = dead_reckoning_trajectory(ds)
    t = np.array([s.t_ref_s for s in build_scans(ds, ScanConfig(), dr).scans])
    ruler_name = "truth" if ds.truth is not None else "gps+ahrs"
    ruler = truth_trajectory(ds) if ds.truth is not None else gps_ahrs_trajectory(ds)
    res: dict[str, Any] = {"source": str(ds.root), "scans": int(t.size), "trajectories": {}}
    counts = {}
    for name, traj in ((ruler_name, ruler), ("dead reckoning", dr)):
        counts[name] = neighbours(traj.poses(t)[:, :2], t, args.radius_m, args.min_gap_s)
        res["trajectories"][name] = allowed(counts[name])
    print(
        f"{res['source']}: {t.size} scans; older scans within {args.radius_m:g} m and "
        f"{args.min_gap_s:g} s, per scan"
    )
    print("| positions | scans with any | sum min(n, 1) | min(n, 2) | min(n, 4) | n |")
    print("|---|---|---|---|---|---|")
    for name, a in res["trajectories"].items():
        print(
            f"| {name} | {a['scans_with_any']} | {a['sum_min_1']} | {a['sum_min_2']} |"
            f" {a['sum_min_4']} | {a['sum_all']} |"
        )
    res["loops"] = {}
    for f in args.loop:
        rows = json.loads(f.read_text())["rows"]
        tried = np.zeros(t.size, dtype=int)
        older: dict[int, list[int]] = defaultdict(list)
        for r in rows:
            k = int(np.argmin(np.abs(t - r["t_k"])))
            tried[k] += 1
            older[k].append(int(np.argmin(np.abs(t - r["t_j"]))))
        gaps = Counter(
            abs(js[a] - js[b]) for js in older.values() for a in range(len(js)) for b in range(a)
        )
        short = int(np.sum(tried < np.minimum(counts[ruler_name], 2)))
        res["loops"][str(f)] = {
            "tried": int(tried.sum()),
            "scans_tried": int(np.sum(tried > 0)),
            "scans_short_of_min_2": short,
            "spacing_of_one_scans_revisits": dict(sorted(gaps.items())),
        }
        print(
            f"{f}: {int(tried.sum())} tried at {int(np.sum(tried > 0))} scans; scans with fewer"
            f" than min(n, 2) by {ruler_name}: {short}; the older scans of one scan's revisits"
            f" are apart by (scans: count) {dict(sorted(gaps.items()))}"
        )
    write_result(res, args.out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
