"""The health monitor's false alarms on clean simulated runs, and its hits on injected faults.

Clean: ``--seeds`` (default the held-back 10000-10019, never tuned on) of the simulated
``--kind`` (default harbour, 600 s), both closed loops with their defaults; a run is a false
alarm when the monitor flags anything (``health_ok`` false). Faults, on the first
``--fault-seeds`` of them: the simulated gyro reads the true rate plus 0.01 rad/s (the marina
MTi's bias) and the configuration lets the AHRS bias walk (0.15 deg/sqrt(s), as the run of the
issue): the EKF with its gyro-bias state held at 0 (prior 1e-6 deg/s) and iSAM2 (which has
none; the runner refuses the combination, so it is run through the closed loop here); and the
line covariances taken 100 times too small (``line_cov_scale`` 0.01); and the AHRS bias's prior
sigma taken as 0.05 deg against the simulated 2 deg (``ahrs_bias_sigma_deg``), which only the
NEES against the truth can see. ``--duration-s`` shortens the runs. Serial, one core:
``taskset -c 0 .venv/bin/python benchmarks/health_monitor.py``.
"""

from __future__ import annotations

import argparse
import tempfile
import time
import warnings
from dataclasses import replace
from pathlib import Path
from typing import Any

from sonarslam.datasets.simulator import make_scenario, simulate_records
from sonarslam.datasets.simulator.writer import write_dataset
from sonarslam.datasets.source import Dataset, open_dataset
from sonarslam.slam.backends.registry import backend_spec
from sonarslam.slam.run.closed_loop import run_closed_loop
from sonarslam.slam.run.health import monitor_run
from sonarslam.slam.run.presets import run_config
from sonarslam.slam.run.run import run_backend
from sonarslam.slam.run.sweep import parse_seeds


def _dataset(
    kind: str,
    seed: int,
    folder: Path,
    gyro_bias_rad_per_s: float = 0.0,
    duration_s: float | None = None,
) -> Dataset:
    scenario = make_scenario(kind, seed, duration_s)
    if gyro_bias_rad_per_s:
        scenario = replace(
            scenario, noise=replace(scenario.noise, ahrs_gyro_bias_rad_per_s=gyro_bias_rad_per_s)
        )
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return open_dataset(write_dataset(simulate_records(scenario), folder))


def _walking(ds: Dataset, walk: float) -> Dataset:
    noise = replace(ds.config.noise, ahrs_bias_walk_deg_per_sqrt_s=walk)
    return replace(ds, config=replace(ds.config, noise=noise))


def _monitored(ds: Dataset, backend: str, settings: dict[str, Any]) -> dict[str, Any]:
    """The closed loop and the monitor, without the runner's up-front refusals."""
    config = run_config(ds.beams, backend, settings, ds.config.noise)
    spec, mount = backend_spec(backend), ds.config.sonar_mounting
    result = run_closed_loop(
        ds,
        lambda t0, p0, c0: spec.make(t0, p0, c0, mount, config.backend),
        config.extractor,
        progress=False,
    )
    return monitor_run(ds, result).metrics()


def _run(ds: Dataset, backend: str, settings: dict[str, Any]) -> dict[str, Any]:
    """The runner's run (its refusals and the monitor)."""
    return run_backend(ds, backend, settings).metrics


def _quiet(call: Any, ds: Dataset, backend: str, settings: dict[str, Any]) -> dict[str, Any]:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return dict(call(ds, backend, settings))


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--kind", default="harbour")
    ap.add_argument("--seeds", default="10000-10019")
    ap.add_argument("--backends", default="ekf,isam2")
    ap.add_argument("--fault-seeds", type=int, default=5)
    ap.add_argument("--duration-s", type=float, default=None, help="default: the kind's own")
    args = ap.parse_args()
    seeds = parse_seeds(args.seeds)
    backends = args.backends.split(",")
    alarms: dict[str, list[str]] = {b: [] for b in backends}
    hits: dict[str, list[bool]] = {}
    work = Path(tempfile.mkdtemp(prefix="sonarslam-health-"))
    t0 = time.perf_counter()
    for i, seed in enumerate(seeds):
        ds = _dataset(args.kind, seed, work / f"clean{seed}", duration_s=args.duration_s)
        for b in backends:
            m = _quiet(_run, ds, b, {})
            if not m["health_ok"]:
                alarms[b].append(f"seed {seed}: {m['health_first_issue']}")
            print(f"clean {args.kind} {seed} {b}: {m['health_line']}", flush=True)
        if i >= args.fault_seeds:
            continue
        bad = _walking(_dataset(args.kind, seed, work / f"gyro{seed}", 0.01, args.duration_s), 0.15)
        faults: dict[str, tuple[Any, Dataset, str, dict[str, Any]]] = {
            "ekf, gyro bias unmodelled + walk": (
                _monitored,
                bad,
                "ekf",
                {"ekf.gyro_bias_sigma_deg_per_s": 1e-6},
            ),
            "isam2, gyro bias + walk": (_monitored, bad, "isam2", {}),
            "ekf, lines 100x overconfident": (_run, ds, "ekf", {"ekf.line_cov_scale": 0.01}),
            "isam2, lines 100x overconfident": (_run, ds, "isam2", {"isam2.line_cov_scale": 0.01}),
            "ekf, AHRS bias prior 0.05 deg": (
                _run,
                ds,
                "ekf",
                {"ekf.noise.ahrs_bias_sigma_deg": 0.05},
            ),
            "isam2, AHRS bias prior 0.05 deg": (
                _run,
                ds,
                "isam2",
                {"isam2.noise.ahrs_bias_sigma_deg": 0.05},
            ),
        }
        for name, (call, data, backend, settings) in faults.items():
            m = _quiet(call, data, backend, settings)
            hits.setdefault(name, []).append(not m["health_ok"])
            print(
                f"fault {name} {seed}: {m['health_flagged']} {m['health_first_issue']}", flush=True
            )
    print(
        f"\n{args.kind}, seeds {args.seeds}, {args.duration_s or 'default'} s of data,"
        f" {time.perf_counter() - t0:.0f} s wall"
    )
    for b in backends:
        print(f"false alarms {b}: {len(alarms[b])} / {len(seeds)}")
        for a in alarms[b]:
            print(f"  {a}")
    for name, flags in hits.items():
        print(f"flagged {name}: {sum(flags)} / {len(flags)}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
