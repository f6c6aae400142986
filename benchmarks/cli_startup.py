"""How fast the command line answers: ``sonarslam --version``, ``sonarslam --help`` and every
``sonarslam COMMAND --help``, as a user types them (the ``sonarslam`` script beside this
interpreter, a fresh process each time), pinned to one core with ``taskset``.

For each command line: the median wall time of ``--runs`` runs (after one unmeasured run that
warms the file cache), the median CPU time of the process (user + system), and how many modules
it imported (``sys.modules`` after the command, in a process of its own). The targets (issue 28):
``--version`` and ``--help`` within 0.5 s, ``COMMAND --help`` within 1 s; before the parsers were
split from the commands every one of them imported the whole library (2,295 modules, 7.7-14 s).
The machine's load average is printed beside the figures, since on a shared machine it decides
the wall times (the CPU times much less).

Usage::

    .venv/bin/python benchmarks/cli_startup.py --runs 5 --out out/cli_startup.json
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import shutil
import statistics
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

from sonarslam.slam.cli.parsers import COMMANDS

#: The targets of issue 28 (s): the bare command's flags, and a command's help.
TARGET_S = {"flag": 0.5, "command": 1.0}

#: Counts the modules a command line imports: run in a fresh interpreter, stdout silenced.
_COUNT = (
    "import contextlib, io, sys\n"
    "from sonarslam.slam.cli.main import main\n"
    "with contextlib.redirect_stdout(io.StringIO()):\n"
    "    try:\n"
    "        main(sys.argv[1:])\n"
    "    except SystemExit:\n"
    "        pass\n"
    "print(len(sys.modules))\n"
)


def _cli() -> list[str]:
    """The ``sonarslam`` script beside this interpreter (what ``make venv`` installs), else the
    module run by this interpreter."""
    script = Path(sys.executable).parent / "sonarslam"
    return [str(script)] if script.is_file() else [sys.executable, "-m", "sonarslam.slam.cli.main"]


def _children_cpu_s() -> float:
    r = resource.getrusage(resource.RUSAGE_CHILDREN)
    return r.ru_utime + r.ru_stime


def time_command(prefix: list[str], argv: list[str], runs: int) -> dict[str, Any]:
    """Median wall and CPU seconds of ``prefix + cli + argv`` over ``runs`` runs, and the
    modules it imports."""
    cmd = [*prefix, *_cli(), *argv]
    subprocess.run(cmd, capture_output=True, check=True)  # warm the file cache
    walls, cpus = [], []
    for _ in range(runs):
        c0, w0 = _children_cpu_s(), time.perf_counter()
        subprocess.run(cmd, capture_output=True, check=True)
        walls.append(time.perf_counter() - w0)
        cpus.append(_children_cpu_s() - c0)
    counted = subprocess.run(
        [*prefix, sys.executable, "-c", _COUNT, *argv], capture_output=True, text=True, check=True
    )
    kind = "flag" if argv[0].startswith("-") else "command"
    wall = statistics.median(walls)
    return {
        "argv": " ".join(argv),
        "wall_s": wall,
        "wall_min_s": min(walls),
        "cpu_s": statistics.median(cpus),
        "modules": int(counted.stdout.split()[-1]),
        "target_s": TARGET_S[kind],
        "within_target": wall <= TARGET_S[kind],
    }


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--runs", type=int, default=5, help="measured runs per command line (default 5)")
    p.add_argument("--cpu", type=int, default=None, help="the core to pin to (default the last)")
    p.add_argument("--out", default=None, help="JSON of the figures")
    args = p.parse_args()
    prefix: list[str] = []
    cpu = args.cpu if args.cpu is not None else max(os.sched_getaffinity(0))
    if shutil.which("taskset"):
        prefix = ["taskset", "-c", str(cpu)]
    else:
        print("taskset not found: not pinned")
    lines = [["--version"], ["--help"], *([name, "--help"] for name, _, _ in COMMANDS)]
    load_before = os.getloadavg()
    rows = [time_command(prefix, argv, args.runs) for argv in lines]
    load_after = os.getloadavg()
    width = max(len(r["argv"]) for r in rows)
    print(f"sonarslam ARGS, median of {args.runs} runs pinned to CPU {cpu if prefix else '-'}:")
    for r in rows:
        mark = "" if r["within_target"] else f"  (over the {r['target_s']:g} s target)"
        print(
            f"  {r['argv']:<{width}}  {r['wall_s']:.3f} s wall (min {r['wall_min_s']:.3f}),"
            f" {r['cpu_s']:.3f} s CPU, {r['modules']} modules{mark}"
        )
    print(
        "load average (1, 5, 15 min): before "
        + ", ".join(f"{x:.2f}" for x in load_before)
        + "; after "
        + ", ".join(f"{x:.2f}" for x in load_after)
        + f" on {os.cpu_count()} CPUs"
    )
    if args.out:
        Path(args.out).parent.mkdir(parents=True, exist_ok=True)
        figures = {
            "runs": args.runs,
            "cpu": cpu if prefix else None,
            "load_before": load_before,
            "load_after": load_after,
            "cpus": os.cpu_count(),
            "commands": rows,
        }
        Path(args.out).write_text(json.dumps(figures, indent=1) + "\n")


if __name__ == "__main__":
    main()
