"""Speed of the EKF back end in closed loop on one core.

The whole marina through the runner (:func:`sonarslam.slam.run.run.run_backend`: the extractor preset of
the beams, :class:`sonarslam.slam.backends.ekf.LineEkf` with its defaults, the anchored odometry as the
extractor's pose source): the real-time factor of the whole loop (data span / wall time,
extractor included), the split between extractor and filter, and the time per vote of lines
(association, updates, landmarks). Without ``$SONARSLAM_DATA/marina`` a simulated harbour
replaces it (as ``isam2_speed.py``).

Usage::

    .venv/bin/python benchmarks/ekf_speed.py --out out/ekf_speed.json
"""

from __future__ import annotations

from common import open_run, pin_one_core  # first: one BLAS thread  # isort: skip

import argparse
import json
from pathlib import Path
from typing import Any

from isam2_speed import REALTIME_FACTOR_MIN

from sonarslam.slam.backends.ekf import LineEkf
from sonarslam.slam.run.run import run_backend


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--source", default="marina", help="marina (default) or a dataset dir")
    parser.add_argument("--out", default="out/ekf_speed.json")
    args = parser.parse_args(argv)
    cpu = pin_one_core()
    label, dataset = open_run(args.source)
    run = run_backend(dataset, "ekf")
    res, m = run.closed_loop, run.metrics
    assert res is not None and isinstance(res.backend, LineEkf)
    t0, t1 = res.trajectory.span_s
    data_s = t1 - t0
    report: dict[str, Any] = {
        "source": label,
        "cpu": cpu,
        "extractor_preset": m["extractor_preset"],
        "data_s": data_s,
        "wall_s": res.wall_s,
        "extractor_s": res.extractor_s,
        "backend_s": res.backend_s,
        "realtime_factor": data_s / res.wall_s,
        "realtime_factor_min": REALTIME_FACTOR_MIN,
        "line_updates": m.get("line_updates", 0),
        "line_update_ms_p50": m.get("line_update_p50_ms", 0.0),
        "line_update_ms_p99": m.get("line_update_p99_ms", 0.0),
        "landmarks": m["landmarks"],
        "state_size": int(res.backend.x.size),
        "ate_mean_m": m["ate_mean_m"],
    }
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(report, indent=2) + "\n")
    print(
        f"{label}: {data_s:.0f} s of data in {res.wall_s:.1f} s ({report['realtime_factor']:.0f}x, "
        f"required >= {REALTIME_FACTOR_MIN:.0f}x); extractor {res.extractor_s:.1f} s, filter "
        f"{res.backend_s:.1f} s; {report['line_updates']} line updates, p50 "
        f"{report['line_update_ms_p50']:.2f} ms, p99 {report['line_update_ms_p99']:.2f} ms;"
        f" {report['landmarks']} landmarks"
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
