"""``make bench``: every benchmark of this folder, each writing its JSON under ``out/``.

* ``machine_speed.py`` (first): the machine's reference workloads, pure Python and numpy, in
  the same run as the figures below (docs/speed.md's table divides by them);
* ``cli_startup.py``: how fast ``sonarslam --version``, ``--help`` and ``COMMAND --help``
  answer, pinned to one core, and how many modules each imports;
* ``extractor_speed.py``: real-time factor of the whole marina extraction on one core, time per
  beam, and voting one sector against scikit-image's ``hough_line``;
* ``extractor_consistency.py``: the pool test over 50 seeds and the NEES of both covariance
  methods on the simulator;
* ``simulator_speed.py``: one drawn world of 1,800 s simulated and written on one core;
* ``ekf_speed.py``: the EKF back end in closed loop on one core, time per line update;
* ``isam2_speed.py``: the GTSAM back end in closed loop on one core, time per iSAM2 update
  (lines, and lines + scans);
* ``association_quality.py``: association precision and recall of both back ends against the
  simulator's walls;
* ``marina_heading.py``: how much of the marina ATE is the absolute heading (skipped without
  the marina);
* ``marina_sonar_timing.py``: the sonar clock offset and keyframe scan direction by map
  sharpness (skipped without the marina);
* ``marina_line_quality.py``: lines extracted with GPS and with dead-reckoning poses against
  wall references fitted through the GPS-projected leading edges (skipped without the marina).

Then ``speed_table.py`` prints docs/speed.md's speed table from them.
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
SCRIPTS: tuple[tuple[str, str, tuple[str, ...]], ...] = (
    ("machine_speed.py", "out/machine_speed.json", ()),
    ("cli_startup.py", "out/cli_startup.json", ()),
    ("extractor_speed.py", "out/extractor_speed.json", ()),
    ("extractor_consistency.py", "out/extractor_consistency.json", ()),
    ("simulator_speed.py", "out/simulator_speed.json", ()),
    ("ekf_speed.py", "out/ekf_speed.json", ()),
    ("isam2_speed.py", "out/isam2_speed.json", ()),
    ("isam2_speed.py", "out/isam2_speed_scans.json", ("--set", "isam2.constraints=lines,scans")),
    ("association_quality.py", "out/association_quality.json", ()),
    ("marina_heading.py", "out/marina_heading.json", ()),
    ("marina_sonar_timing.py", "out/marina_sonar_timing.json", ()),
    ("marina_line_quality.py", "out/marina_line_quality.json", ()),
)


def main() -> int:
    # one process each: the speed benchmark pins itself to one CPU and sets the BLAS threads
    for script, out, extra in SCRIPTS:
        print(f"== {script} {' '.join(extra)}", flush=True)
        rc = subprocess.call([sys.executable, str(HERE / script), *extra, "--out", out])
        if rc != 0:
            return rc
    return subprocess.call([sys.executable, str(HERE / "speed_table.py"), "--dir", "out"])


if __name__ == "__main__":
    sys.exit(main())
