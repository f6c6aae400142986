"""``make bench``: every benchmark of this folder, each writing its JSON under ``out/``.

* ``extractor_speed.py``: real-time factor of the whole marina extraction on one core, time per
  beam, and voting one sector against scikit-image's ``hough_line``;
* ``extractor_consistency.py``: the pool test over 50 seeds and the NEES of both covariance
  methods on the simulator;
* ``simulator_speed.py``: one drawn world of 1,800 s simulated and written on one core;
* ``ekf_speed.py``: the EKF back end in closed loop on one core, time per line update;
* ``isam2_speed.py``: the GTSAM back end in closed loop on one core, time per iSAM2 update;
* ``association_quality.py``: association precision and recall of both back ends against the
  simulator's walls;
* ``marina_heading.py``: how much of the marina ATE is the absolute heading (skipped without
  the marina);
* ``marina_sonar_timing.py``: the sonar clock offset and keyframe scan direction by map
  sharpness (skipped without the marina);
* ``marina_line_quality.py``: lines extracted with GPS and with dead-reckoning poses against
  wall references fitted through the GPS-projected leading edges (skipped without the marina).
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
SCRIPTS = (
    ("extractor_speed.py", "out/extractor_speed.json"),
    ("extractor_consistency.py", "out/extractor_consistency.json"),
    ("simulator_speed.py", "out/simulator_speed.json"),
    ("ekf_speed.py", "out/ekf_speed.json"),
    ("isam2_speed.py", "out/isam2_speed.json"),
    ("association_quality.py", "out/association_quality.json"),
    ("marina_heading.py", "out/marina_heading.json"),
    ("marina_sonar_timing.py", "out/marina_sonar_timing.json"),
    ("marina_line_quality.py", "out/marina_line_quality.json"),
)


def main() -> int:
    # one process each: the speed benchmark pins itself to one CPU and sets the BLAS threads
    for script, out in SCRIPTS:
        print(f"== {script}", flush=True)
        rc = subprocess.call([sys.executable, str(HERE / script), "--out", out])
        if rc != 0:
            return rc
    return 0


if __name__ == "__main__":
    sys.exit(main())
