"""The machine's own speed: a fixed pure-Python loop and a fixed numpy workload, one core.

Speeds measured on two machines (or on one machine under two loads) compare only through a
reference timed in the same run: this is it. Both workloads are fixed (no data, no randomness
that varies) and timed ``--repeats`` times pinned to one core with one BLAS thread; the median
and the minimum are reported (the minimum is the machine, the median the machine under its
load). ``make bench`` runs it first; :mod:`speed_table` divides by it.

* ``python_loop``: ten million steps of an integer loop with a branch and a float add (what the
  closed loops' per-record Python costs scale with);
* ``numpy_small``: 20,000 rounds of the small-array calls a vote makes (7 x 7 products,
  100-element reductions and a 2,000-element sort);
* ``numpy_blas``: twenty 400 x 400 matrix products and a 10^6-element sort.

Usage::

    .venv/bin/python benchmarks/machine_speed.py --out out/machine_speed.json
"""

from __future__ import annotations

from common import pin_one_core  # first: one BLAS thread  # isort: skip

import argparse
import json
import os
import platform
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np


def python_loop() -> float:
    acc = 0.0
    for i in range(10_000_000):
        if i & 1:
            acc += 1.5
    return acc


def numpy_small() -> float:
    a = np.arange(49, dtype=np.float64).reshape(7, 7) / 49.0
    v = np.linspace(0.0, 1.0, 100)
    s = np.linspace(1.0, 0.0, 2000)
    out = 0.0
    for _ in range(20_000):
        out += float((a @ a.T)[0, 0]) + float(v.sum()) + float(np.max(v))
    for _ in range(200):
        out += float(np.sort(s)[0])
    return out


def numpy_blas() -> float:
    m = np.arange(160_000, dtype=np.float64).reshape(400, 400) % 7.0
    out = 0.0
    for _ in range(20):
        out += float((m @ m)[0, 0])
    out += float(np.sort(np.arange(1_000_000, dtype=np.float64)[::-1] % 1013.0)[0])
    return out


WORKLOADS: dict[str, Callable[[], float]] = {
    "python_loop": python_loop,
    "numpy_small": numpy_small,
    "numpy_blas": numpy_blas,
}


def measure(repeats: int) -> dict[str, Any]:
    """Median and minimum wall time of each workload (s), and the machine it ran on."""
    cpu = pin_one_core()
    out: dict[str, Any] = {
        "cpu": cpu,
        "machine": platform.machine(),
        "processor": _cpu_model(),
        "python": platform.python_version(),
        "numpy": np.__version__,
        "load_avg": list(os.getloadavg()) if hasattr(os, "getloadavg") else None,
    }
    for name, fn in WORKLOADS.items():
        t = []
        for _ in range(repeats):
            a = time.perf_counter()
            fn()
            t.append(time.perf_counter() - a)
        out[f"{name}_s_median"] = float(np.median(t))
        out[f"{name}_s_min"] = float(np.min(t))
    return out


def _cpu_model() -> str:
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "unknown"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--out", default="out/machine_speed.json")
    args = parser.parse_args(argv)
    res = measure(args.repeats)
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(res, indent=2) + "\n")
    print(
        f"{res['processor']}, cpu {res['cpu']}, load {res['load_avg']}: python loop "
        f"{res['python_loop_s_median']:.2f} s (min {res['python_loop_s_min']:.2f}), numpy small "
        f"{res['numpy_small_s_median']:.2f} s, numpy BLAS {res['numpy_blas_s_median']:.2f} s"
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
