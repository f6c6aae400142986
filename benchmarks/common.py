"""What the benchmark scripts share (they run as ``python benchmarks/NAME.py``, so this folder is
on ``sys.path``). Import it first: it sets the BLAS thread pools to one thread before numpy
loads."""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import json  # noqa: E402
import tempfile  # noqa: E402
from pathlib import Path  # noqa: E402

from sonarslam.datasets.simulator import simulate  # noqa: E402
from sonarslam.datasets.source import Dataset, data_root, open_dataset  # noqa: E402


def pin_one_core() -> int | None:
    """Pin this process to the first CPU it may use; the CPU, or None where unsupported."""
    if not hasattr(os, "sched_setaffinity"):
        return None
    cpu = min(os.sched_getaffinity(0))
    os.sched_setaffinity(0, {cpu})
    return cpu


def open_run(source: str) -> tuple[str, Dataset]:
    """The marina, a dataset directory, or a simulated harbour (600 s, seed 1) when the marina
    is absent; with a label that says which."""
    root = data_root()
    if source == "marina" and root is not None and (root / "marina").is_dir():
        return "marina", open_dataset("marina")
    if source != "marina":
        return str(source), open_dataset(source)
    out = Path(tempfile.mkdtemp(prefix="benchmark_"))
    label = "simulated harbour seed 1, 600 s: the marina was not found under $SONARSLAM_DATA"
    return label, open_dataset(simulate("harbour", 1, out))


def write_result(result: dict[str, object], out: Path | None) -> None:
    """A benchmark's result as indented JSON to ``out`` (its folder made), said on stdout; nothing
    when ``out`` is None."""
    if out is None:
        return
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(result, indent=1) + "\n")
    print(f"written {out}")
