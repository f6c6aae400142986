"""What the benchmark scripts share (they run as ``python benchmarks/NAME.py``, so this folder is
on ``sys.path``)."""

from __future__ import annotations

import os


def pin_one_core() -> int | None:
    """Pin this process to the first CPU it may use; the CPU, or None where unsupported."""
    if not hasattr(os, "sched_setaffinity"):
        return None
    cpu = min(os.sched_getaffinity(0))
    os.sched_setaffinity(0, {cpu})
    return cpu
