"""docs/speed.md's speed table: rendered from make bench's JSON, put between its markers."""

from __future__ import annotations

import importlib.util
import json
import sys
from pathlib import Path
from types import ModuleType

ROOT = Path(__file__).resolve().parent.parent


def _script(name: str) -> ModuleType:
    sys.path.insert(0, str(ROOT / "benchmarks"))  # the scripts import benchmarks/common.py
    spec = importlib.util.spec_from_file_location(name, ROOT / "benchmarks" / f"{name}.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_the_table_holds_each_runs_figures_and_goes_between_the_markers(tmp_path: Path) -> None:
    st = _script("speed_table")
    machine = {"processor": "CPU X", "cpu": 1, "python": "3.11.7", "numpy": "2.4.6",
               "load_avg": [0.5, 0.4, 0.3], "python_loop_s_median": 1.25,
               "numpy_small_s_median": 0.5, "numpy_blas_s_median": 0.75}  # fmt: skip
    ekf = {"realtime_factor": 612.4, "extractor_s": 2.5, "backend_s": 2.0, "wall_s": 5.46,
           "line_update_ms_p50": 1.25, "line_update_ms_p99": 4.5}  # fmt: skip
    isam = {"realtime_factor": 655.0, "extractor_s": 2.5, "backend_s": 2.0, "wall_s": 5.1,
            "isam_update_ms_p50": 0.6, "isam_update_ms_p99": 9.0, "isam_update_ms_max": 54.0}  # fmt: skip
    for name, rec in [("machine_speed", machine), ("ekf_speed", ekf), ("isam2_speed", isam)]:
        (tmp_path / f"{name}.json").write_text(json.dumps(rec))
    text = st.table(tmp_path)
    assert "CPU X" in text and "pure-Python loop 1.25 s" in text
    assert "| EKF closed loop (`ekf_speed.py`) | 612× |" in text
    assert "max 54 ms" in text and "lines + scans" not in text  # its file is missing
    readme = tmp_path / "README.md"
    readme.write_text(f"# x\n\n{st.BEGIN}\nold\n{st.END}\n\nafter\n")
    st.put_in_readme(readme, text)
    assert readme.read_text() == f"# x\n\n{st.BEGIN}\n{text}\n{st.END}\n\nafter\n"
    assert st.BEGIN in (ROOT / "docs" / "speed.md").read_text()


def test_the_reference_workloads_are_fixed() -> None:
    ms = _script("machine_speed")
    assert ms.python_loop() == 1.5 * 5_000_000
    assert ms.numpy_small() == ms.numpy_small()
