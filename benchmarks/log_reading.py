"""Opening a dataset in the marina layout: ``open_dataset`` (the text logs read, the gates, the
sonar's beams) on the marina and on a simulated harbour (its raw ``*_IS.log`` of intensities),
CPU and wall time of each, on one core.

Each source is opened once unmeasured (it warms the file cache and the keyframes' cache), then
``--runs`` times; the minimum and median CPU time (the process's, user + system) and the
minimum wall time are reported, with the machine's load average, since on a shared machine the
load decides the wall times (the CPU times much less). The test suite opens datasets of this
layout many times (every simulated world is written in it), so this is also the suite's time.

Usage::

    taskset -c 1 .venv/bin/python benchmarks/log_reading.py --runs 5 --out out/log_reading.json
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import tempfile
import time
import warnings
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parent))

from common import pin_one_core, write_result  # noqa: E402

from sonarslam.datasets.simulator import simulate  # noqa: E402
from sonarslam.datasets.source import data_root, open_dataset  # noqa: E402


def measure(source: str | Path, runs: int) -> dict[str, Any]:
    """CPU (min, median) and wall (min) seconds of ``open_dataset(source)`` over ``runs``."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the sensor gates' counted warnings, once per open
        open_dataset(source)
        cpu, wall = [], []
        for _ in range(runs):
            c, w = time.process_time(), time.perf_counter()
            open_dataset(source)
            cpu.append(time.process_time() - c)
            wall.append(time.perf_counter() - w)
    return {
        "cpu_min_s": round(min(cpu), 3),
        "cpu_median_s": round(statistics.median(cpu), 3),
        "wall_min_s": round(min(wall), 3),
    }


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--runs", type=int, default=5)
    ap.add_argument("--harbour-s", type=float, default=300.0, help="simulated harbour length")
    ap.add_argument("--out", type=Path, default=None)
    args = ap.parse_args(argv)
    cpu = pin_one_core()
    rows: dict[str, Any] = {}
    root = data_root()
    if root is not None and (root / "marina").is_dir():
        rows["marina"] = measure("marina", args.runs)
    with tempfile.TemporaryDirectory(prefix="log_reading_") as tmp:
        harbour = simulate("harbour", 2, Path(tmp) / "h", duration_s=args.harbour_s)
        rows[f"simulated harbour, {args.harbour_s:g} s"] = measure(harbour, args.runs)
    load = os.getloadavg()[0]
    for name, row in rows.items():
        print(
            f"{name}: open_dataset cpu {row['cpu_min_s']:.3f} s (median {row['cpu_median_s']:.3f}),"
            f" wall {row['wall_min_s']:.3f} s"
        )
    print(f"one core (cpu {cpu}), load average {load:.2f}, {args.runs} runs each")
    write_result({"rows": rows, "runs": args.runs, "cpu": cpu, "load_1min": load}, args.out)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
