"""Reading a Ping Viewer ``.bin`` log: speed against real time and peak memory against the log's
length.

Writes, for each length asked, a Ping360 log as Ping Viewer lays it out
(:func:`sonarslam.datasets.ping360.write_ping360_log`: ``device_data`` beams of 1200 samples at
25 Hz, two gradians apart; faster than a Ping360 at 50 m, so more data per second than a real
log) and a navigation CSV (DVL 5 Hz, AHRS 50 Hz), then reads each in a fresh process: the log
alone (:func:`~sonarslam.datasets.ping360.read_ping360_log`) and the whole dataset with its
navigation and gates (:func:`~sonarslam.datasets.ping360.open_ping360`). Reports the wall time,
the real-time factor, the process's peak resident memory (``VmHWM``), its peak before the reading and the
beams' own array (which a run holds: what the reading adds beyond it must not grow with the
log)::

    taskset -c 1 .venv/bin/python benchmarks/ping360_reading.py --minutes 5 20
    taskset -c 1 .venv/bin/python benchmarks/ping360_reading.py --minutes 5 20 --split

``--split``: the records as Ping Viewer writes them from a serial link (a record a read of
the link, ``write_ping360_log``'s ``split_rng``: each message over two or three records).

Target (issue 30): >= 50x real time on one core.
"""

from __future__ import annotations

import argparse
import json
import math
import subprocess
import sys
import tempfile
import time
import warnings
from pathlib import Path

import numpy as np

SONAR_HZ, DVL_HZ, AHRS_HZ = 25.0, 5.0, 50.0
N_SAMPLES, SAMPLE_PERIOD_TICKS = 1200, 2222  # ~50 m at 1500 m/s
START_MS = 1_700_000_000_000  # the log's start (Unix ms): its file name


def write(folder: Path, minutes: float, split: bool = False) -> tuple[Path, Path]:
    """A log of ``minutes`` and its navigation CSV in ``folder``; its records split as a
    serial link delivers them when ``split``."""
    from sonarslam.datasets.ping360 import log_file_name, write_ping360_log

    rng = np.random.default_rng(0)
    n = int(60.0 * minutes * SONAR_HZ)
    stamps = 500 + np.rint(np.arange(n) * 1000.0 / SONAR_HZ).astype(np.int64)
    grads = (2 * np.arange(n)) % 400
    bins = rng.integers(0, 60, (n, N_SAMPLES), dtype=np.uint8)
    log = write_ping360_log(
        folder / log_file_name(START_MS),
        stamps,
        grads,
        bins,
        SAMPLE_PERIOD_TICKS,
        split_rng=np.random.default_rng(1) if split else None,
    )
    t0 = START_MS / 1000.0
    lines = ["t_s,dvl_vx_mps,dvl_vy_mps,ahrs_yaw_enu_rad,ahrs_yaw_rate_rad_per_s"]
    for k in range(int(60.0 * minutes * AHRS_HZ) + 60):
        t = t0 + k / AHRS_HZ
        yaw = math.remainder(0.01 * k / AHRS_HZ, 2 * math.pi)
        dvl = "0.5,0.0" if k % int(AHRS_HZ / DVL_HZ) == 0 else ","
        lines.append(f"{t!r},{dvl},{yaw!r},0.01")
    nav = folder / "nav.csv"
    nav.write_text("\n".join(lines) + "\n")
    return log, nav


def read(log: Path, nav: Path, whole: bool) -> dict[str, float]:
    """Read in this process: wall time, data span, peak RSS, the beams' bytes."""
    from sonarslam.datasets.errors import DataWarning
    from sonarslam.datasets.ping360 import open_ping360, read_ping360_log

    before = _status_mb("VmHWM")
    t0 = time.perf_counter()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DataWarning)
        beams = open_ping360(log, nav=nav).beams if whole else read_ping360_log(log).beams
    wall = time.perf_counter() - t0
    span = float(beams.t_s[-1] - beams.t_s[0])
    return {
        "wall_s": wall,
        "data_s": span,
        "realtime_factor": span / wall,
        "peak_rss_mb": _status_mb("VmHWM"),
        "rss_before_read_mb": before,
        "beams_mb": beams.intensities.nbytes / 2**20,
        "beams": len(beams),
    }


def _status_mb(key: str) -> float:
    """A memory figure of this process from ``/proc/self/status`` (MB): ``VmHWM`` is the peak
    resident set of this process image alone (``getrusage``'s ``ru_maxrss`` keeps the peak of
    the parent that forked it, which held the log it wrote)."""
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith(f"{key}:"):
            return float(line.split()[1]) / 1024.0
    return float("nan")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--minutes", type=float, nargs="+", default=[5.0, 20.0])
    ap.add_argument("--split", action="store_true", help="records split as a serial link reads")
    ap.add_argument("--read", nargs=3, help=argparse.SUPPRESS)  # the child: LOG NAV WHOLE
    args = ap.parse_args()
    if args.read:
        log, nav, whole = args.read
        print(json.dumps(read(Path(log), Path(nav), whole == "1")))
        return 0
    with tempfile.TemporaryDirectory() as tmp:
        for minutes in args.minutes:
            folder = Path(tmp) / f"{minutes:g}min"
            folder.mkdir()
            log, nav = write(folder, minutes, args.split)
            for whole in ("0", "1"):
                out = subprocess.run(
                    [sys.executable, __file__, "--read", str(log), str(nav), whole],
                    check=True,
                    capture_output=True,
                    text=True,
                ).stdout
                row = {
                    "minutes": minutes,
                    "records": "split" if args.split else "a message each",
                    "what": "dataset (log + CSV nav + gates)" if whole == "1" else "log alone",
                    "log_mb": log.stat().st_size / 2**20,
                    **json.loads(out),
                }
                print(json.dumps(row))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
