"""Run a speed benchmark with its timers reading this process's CPU time, not the wall clock.

On a machine shared with other work the wall clock counts the time the process waited for a
core; CPU time counts what it ran. This runs ``benchmarks/<script>`` of a checkout (``--repo``,
default this one: main's for the "before" figures, so both are timed the same way) with
``time.perf_counter`` replaced by ``time.process_time`` before anything imports it, so every
figure the script reports (loop, extractor, back end, per update, per beam) is CPU seconds.
The benchmark is single-threaded (one BLAS thread, no numba threads), so the two agree on an
idle machine.

Usage::

    taskset -c 1 .venv/bin/python benchmarks/cpu_time.py ekf_speed.py --out out/ekf_cpu.json
    taskset -c 1 /work/main/.venv/bin/python benchmarks/cpu_time.py --repo /work/main \\
        ekf_speed.py --out out/ekf_cpu_main.json
"""

from __future__ import annotations

import os
import runpy
import sys
import time
from pathlib import Path


def main(argv: list[str]) -> int:
    repo = Path(__file__).resolve().parent.parent
    if argv[:1] == ["--repo"]:
        repo, argv = Path(argv[1]).resolve(), argv[2:]
    if not argv:
        print(__doc__)
        return 2
    script, args = argv[0], argv[1:]
    time.perf_counter = time.process_time  # every timer of the benchmark: CPU time
    sys.path[:0] = [str(repo / "benchmarks"), str(repo)]
    os.chdir(repo)
    sys.argv = [script, *args]
    try:
        runpy.run_path(str(repo / "benchmarks" / script), run_name="__main__")
    except SystemExit as stop:
        return int(stop.code or 0)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
