"""The marina's sonar clock offset and keyframe scan direction by map sharpness, GPS-free.

.venv/bin/python benchmarks/marina_sonar_timing.py [--out FILE.json]

Both settings decide when each keyframe beam was taken, so both smear the motion-corrected map
when wrong. With dead-reckoning poses (no GPS), this prints the summed entropy of 0.5 m
histograms of the projected bins over 60 s windows (:func:`sonarslam.slam.run.calibration.scan_entropy`;
lower is sharper) for the scan direction (-1: the head turns toward decreasing angle, the
configured value; +1: the data README's reading) and for sonar clock offsets 0-1 s. Values
compare only within this script (one dataset, one pose source, one window).
"""

from __future__ import annotations

import argparse
import json
import tempfile
from pathlib import Path

from sonarslam.datasets.errors import DataError
from sonarslam.datasets.source import open_dataset
from sonarslam.slam.run.calibration import scan_entropy
from sonarslam.slam.run.sources import dead_reckoning_trajectory


def entropy_with(toml_text: str) -> float:
    """Entropy of the marina read with ``toml_text`` over its configuration (--config)."""
    with tempfile.NamedTemporaryFile("w", suffix=".toml", delete=False) as f:
        f.write(toml_text)
    ds = open_dataset("marina", config_override=f.name)
    Path(f.name).unlink()
    return scan_entropy(ds, dead_reckoning_trajectory(ds))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", default=None, help="results JSON")
    args = parser.parse_args()
    try:
        base = open_dataset("marina")
    except DataError as exc:
        print(f"skipped: {exc}")
        return
    result: dict[str, dict[str, float]] = {"scan_direction": {}, "time_offset_s": {}}
    print("summed entropy of 60 s windows, dead-reckoning poses (lower: sharper)")
    for direction in (-1, 1):
        e = entropy_with(f"[keyframes]\nscan_direction = {direction}\n")
        result["scan_direction"][str(direction)] = e
        mark = "  (configured)" if direction == base.config.keyframe_scan_direction else ""
        print(f"  scan direction {direction:+d}: {e:.1f}{mark}")
    for offset in (0.0, 0.25, 0.5, 0.75, 1.0):
        e = entropy_with(f"[sonar]\ntime_offset_s = {offset}\n")
        result["time_offset_s"][str(offset)] = e
        mark = "  (configured)" if offset == base.config.sonar_time_offset_s else ""
        print(f"  sonar clock offset {offset:.2f} s: {e:.1f}{mark}")
    if args.out:
        Path(args.out).write_text(json.dumps(result, indent=1) + "\n")


if __name__ == "__main__":
    main()
