"""Speed of the EKF back end in closed loop on one core (issue: >= 100x real time).

The whole marina with the closed-loop extractor settings (:func:`slam.run.run.default_extractor_config`)
and :class:`slam.backends.ekf.LineEkf` with its defaults, the anchored odometry as the extractor's pose
source: the real-time factor of the whole loop (data span / wall time, extractor included), the
split between extractor and filter, and the time per line update (one per vote with lines).
Without ``$SONARSLAM_DATA/marina`` a simulated harbour replaces it (as ``isam2_speed.py``).

Usage::

    .venv/bin/python benchmarks/ekf_speed.py --out out/ekf_speed.json
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import json  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402
from typing import Any  # noqa: E402

import numpy as np  # noqa: E402
from common import pin_one_core  # noqa: E402
from isam2_speed import REALTIME_FACTOR_MIN, open_run  # noqa: E402


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--source", default="marina", help="marina (default) or a dataset dir")
    parser.add_argument("--out", default="out/ekf_speed.json")
    args = parser.parse_args(argv)
    cpu = pin_one_core()

    from slam.backends.ekf import EkfConfig, LineEkf
    from slam.eval.ate import ate_against_gps
    from slam.run.closed_loop import run_closed_loop

    label, dataset, extractor_config = open_run(args.source)
    mount = dataset.config.sonar_mounting
    update_s: list[float] = []

    class TimedEkf(LineEkf):
        def update_lines(self, features):  # type: ignore[no-untyped-def]
            a = time.perf_counter()
            out = super().update_lines(features)
            update_s.append(time.perf_counter() - a)
            return out

    res = run_closed_loop(
        dataset,
        lambda t, p, c: TimedEkf(t, p, c, mount, EkfConfig()),
        extractor_config,
        progress=False,
    )
    t0, t1 = res.trajectory.span_s
    data_s = t1 - t0
    up = np.array(update_s) if update_s else np.zeros(1)
    report: dict[str, Any] = {
        "source": label,
        "cpu": cpu,
        "data_s": data_s,
        "wall_s": res.wall_s,
        "extractor_s": res.extractor_s,
        "backend_s": res.backend_s,
        "realtime_factor": data_s / res.wall_s,
        "realtime_factor_min": REALTIME_FACTOR_MIN,
        "line_updates": len(update_s),
        "line_update_ms_p50": float(1e3 * np.percentile(up, 50)),
        "line_update_ms_p99": float(1e3 * np.percentile(up, 99)),
        "landmarks": len(res.backend.landmarks),
        "state_size": int(res.backend.x.size),
    }
    if dataset.gps is not None:
        report["ate_mean_m"] = ate_against_gps(res.trajectory, dataset.gps).ate_mean_m
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(report, indent=2) + "\n")
    print(
        f"{label}: {data_s:.0f} s of data in {res.wall_s:.1f} s ({report['realtime_factor']:.0f}x, "
        f"required >= {REALTIME_FACTOR_MIN:.0f}x); extractor {res.extractor_s:.1f} s, filter "
        f"{res.backend_s:.1f} s; {len(update_s)} line updates, p50 "
        f"{report['line_update_ms_p50']:.2f} ms, p99 {report['line_update_ms_p99']:.2f} ms;"
        f" {report['landmarks']} landmarks"
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
