"""Reading an hour of a BlueROV2's QGroundControl ``.tlog`` (``read_tlog``): wall and CPU
time, the factor over real time (issue 41's target: at least 50x) and the peak of the memory
the reader allocated (``tracemalloc``, a separate read: it slows the reading down) beside the
file's size, on one core.

The log: 140 records a second of six types as a BlueROV2's telemetry holds them (``ATTITUDE``
20 Hz, ``LOCAL_POSITION_NED`` 10, ``VISION_POSITION_DELTA`` 5, ``SCALED_IMU2`` 10,
``HEARTBEAT`` 1, ``SERVO_OUTPUT_RAW`` 94: the reader's streams and the many it only counts),
the payloads repeated, every record's stamp its own; ``--corrupt`` chunks overwritten.

Usage::

    taskset -c 1 .venv/bin/python benchmarks/navlog_reading.py --hours 1 --out out/navlog.json
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
import tracemalloc
import warnings
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from common import pin_one_core, write_result  # noqa: E402

from sonarslam.datasets.mavlink import read_tlog  # noqa: E402
from sonarslam.datasets.simulator.bluerov import BUSY_RATES_HZ, write_busy_tlog  # noqa: E402


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--hours", type=float, default=1.0)
    ap.add_argument("--corrupt", type=int, default=20, help="corrupt chunks (200 bytes each)")
    ap.add_argument("--out", type=Path, default=None)
    args = ap.parse_args(argv)
    cpu = pin_one_core()
    span = args.hours * 3600.0
    with tempfile.TemporaryDirectory(prefix="navlog_reading_") as tmp:
        path = write_busy_tlog(Path(tmp) / "hour.tlog", span, args.corrupt)
        size = path.stat().st_size
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # the corrupt chunks' counted warning
            c, w = time.process_time(), time.perf_counter()
            log = read_tlog(path)
            cpu_s, wall_s = time.process_time() - c, time.perf_counter() - w
            tracemalloc.start()
            read_tlog(path)
            peak = tracemalloc.get_traced_memory()[1]
            tracemalloc.stop()
    row = {
        "span_s": span,
        "records": int(span * sum(BUSY_RATES_HZ.values())),
        "file_bytes": size,
        "wall_s": round(wall_s, 3),
        "cpu_s": round(cpu_s, 3),
        "realtime_factor": round(span / wall_s, 1),
        "peak_traced_bytes": peak,
        "corrupt_chunks": log.counts["navlog_corrupt_chunks"],
    }
    load = os.getloadavg()[0]
    print(
        f"{args.hours:g} h of .tlog ({size / 1e6:.1f} MB, {row['records']} records,"
        f" {row['corrupt_chunks']} corrupt chunks): read in {wall_s:.2f} s wall, {cpu_s:.2f} s"
        f" cpu, {row['realtime_factor']:.0f}x real time; peak memory {peak / 1e6:.1f} MB"
        f" ({peak / size:.2f} of the file); one core (cpu {cpu}), load {load:.2f}"
    )
    write_result({"row": row, "cpu": cpu, "load_1min": load}, args.out)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
