"""Speed of the simulator on one core: one drawn world of 1,800 s, from its seed to its files.

For each seed (tuning seeds by default: a speed benchmark tunes nothing, but the held-back range
stays untouched anyway), the wall time of each stage: drawing the world and its route
(:func:`sonarslam.datasets.simulator.drawn_world`), the rest of the simulation in memory (true motion, the
MSIS beams, DVL, AHRS, GPS: :func:`sonarslam.datasets.simulator.simulate_records`), and writing the run in
the marina layout (:func:`sonarslam.datasets.simulator.write_dataset`); their sum is what ``sonarslam
simulate drawn`` takes (the issue's target: 20 s). The process is pinned to one CPU and the BLAS
thread pools to one thread before numpy loads; the machine's load average is printed beside the
figures, since on a shared machine it decides them.

Usage::

    .venv/bin/python benchmarks/simulator_speed.py --seeds 1-3 --out out/simulator_speed.json
"""

from __future__ import annotations

from common import pin_one_core  # first: one BLAS thread  # isort: skip

import argparse
import json
import os
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

from sonarslam.datasets.simulator import make_scenario, make_world, simulate_records, write_dataset
from sonarslam.slam.run.sweep import parse_seeds


def time_seed(seed: int, kind: str, duration_s: float) -> dict[str, Any]:
    """Wall and CPU times (s) of one simulation's stages."""
    scenario = make_scenario(kind, seed, duration_s)
    wall, cpu = [time.perf_counter()], [time.process_time()]

    def lap() -> None:
        wall.append(time.perf_counter())
        cpu.append(time.process_time())

    world = make_world(scenario)
    lap()
    sim = simulate_records(scenario)  # draws the world again: its time is taken off below
    lap()
    with tempfile.TemporaryDirectory() as tmp:
        write_dataset(sim, tmp)
        lap()
    w, c = np.diff(wall), np.diff(cpu)
    return {
        "seed": seed,
        "walls": int(world.walls_m.shape[0]),
        "beams": len(sim.beams),
        "draw_world_s": float(w[0]),
        "simulate_s": float(w[1] - w[0]),
        "write_s": float(w[2]),
        "total_s": float(w[1] + w[2]),
        # what the wall time is on an idle core, whatever the machine's load
        "total_cpu_s": float(c[1] + c[2]),
    }


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--seeds", default="1-3", help="seeds (default 1-3)")
    p.add_argument("--kind", default="drawn")
    p.add_argument("--duration", type=float, default=1800.0, help="simulated seconds")
    p.add_argument("--out", default=None, help="JSON of the figures")
    args = p.parse_args()
    cpu = pin_one_core()
    rows = [time_seed(s, args.kind, args.duration) for s in parse_seeds(args.seeds)]
    load = os.getloadavg()
    for r in rows:
        print(
            f"seed {r['seed']}: {r['walls']} walls, {r['beams']} beams: draw {r['draw_world_s']:.1f}"
            f" s, simulate {r['simulate_s']:.1f} s, write {r['write_s']:.1f} s, total"
            f" {r['total_s']:.1f} s wall, {r['total_cpu_s']:.1f} s CPU"
        )
    totals = np.array([r["total_s"] for r in rows])
    cpu_s = np.array([r["total_cpu_s"] for r in rows])
    print(
        f"{args.kind}, {args.duration:g} s on CPU {cpu}: total median {np.median(totals):.1f} s"
        f" wall (max {totals.max():.1f}), {np.median(cpu_s):.1f} s CPU (max {cpu_s.max():.1f});"
        f" target 20 s; load average {load[0]:.1f} / {load[1]:.1f} / {load[2]:.1f} on"
        f" {os.cpu_count()} CPUs"
    )
    if args.out:
        Path(args.out).parent.mkdir(parents=True, exist_ok=True)
        Path(args.out).write_text(
            json.dumps({"rows": rows, "load_average": load, "cpu": cpu}, indent=1) + "\n"
        )


if __name__ == "__main__":
    main()
