"""What a run's graph knows about the sonar mounting's yaw and the DVL misalignment together.

Rotating the sonar mounting's yaw and the DVL misalignment by one angle (and the mounting's
lever arm with them) turns the dead-reckoned track about its start and the sonar's map with it,
and leaves every AHRS heading alone: every factor stays as satisfied as before. If that is so,
the data say nothing about the two angles' sum, and only the priors decide it. This reads a
run's ``graph.json`` (written with ``isam2.estimate_sonar_mount`` and
``isam2.estimate_misalignment`` on), takes the joint marginal covariance ``Sigma`` of (mounting
yaw, misalignment) at the run's estimate, and removes the two priors' information:
``I_data = Sigma^-1 - diag(1/sigma_yaw^2, 1/sigma_delta^2)`` (exact in the linearisation: the
two priors are independent of everything else). Its information along the difference
``(1, -1)/sqrt(2)`` and along the sum ``(1, 1)/sqrt(2)`` are reported as sigmas (deg).

With GPS in the run folder (``gps.tum``, the marina's) it also reports, **as a ruler only**, the
rotation of the rigid fit of each trajectory onto GPS over the sonar span: a run whose
misalignment turns the whole track shows it there, the aligned error does not.

    .venv/bin/python benchmarks/calibration_gauge.py RUN_DIR [RUN_DIR ...] --out result.json
"""

from __future__ import annotations

import common  # noqa: F401  # first: one BLAS thread  # isort: skip
from common import write_result  # isort: skip

import argparse
import json
import math
from pathlib import Path
from typing import Any

import gtsam
import numpy as np
from evo.core.geometry import umeyama_alignment

from sonarslam.slam.backends.isam2.graph_io import load_graph
from sonarslam.slam.io.trajectory import read_tum


def joint_information(run: Path) -> dict[str, Any]:
    """The joint marginal of (mounting yaw, misalignment) of ``run``'s graph and the data's
    information on their difference and sum (module docstring)."""
    graph, values = load_graph(run / "graph.json")
    C, D = gtsam.symbol("c", 0), gtsam.symbol("d", 0)
    if not (values.exists(C) and values.exists(D)):
        return {}
    isam = json.loads((run / "graph.json").read_text())["meta"]["config"]
    sigma_yaw = float(isam.get("sonar_mount_sigma_deg", 0.5))
    sigma_d = float(isam.get("misalignment_sigma_deg", 5.0))
    joint = gtsam.Marginals(graph, values).jointMarginalCovariance(gtsam.KeyVector([C, D]))
    r2d = math.degrees(1.0)
    var_yaw = float(np.asarray(joint.at(C, C))[2, 2]) * r2d**2
    var_d = float(np.asarray(joint.at(D, D))[0, 0]) * r2d**2
    cross = float(np.asarray(joint.at(C, D))[2, 0]) * r2d**2
    sigma = np.array([[var_yaw, cross], [cross, var_d]])
    prior = np.diag([1.0 / sigma_yaw**2, 1.0 / sigma_d**2])
    if isam.get("sonar_yaw_prior") == "dead_reckoning":  # the yaw's prior on yaw - delta
        prior = prior + np.array([[0.0, -1.0], [-1.0, 1.0]]) / sigma_yaw**2
    info = np.linalg.inv(sigma) - prior
    diff = np.array([1.0, -1.0]) / math.sqrt(2.0)
    total = np.array([1.0, 1.0]) / math.sqrt(2.0)
    i_diff, i_sum = float(diff @ info @ diff), float(total @ info @ total)
    return {
        "yaw_deg": math.degrees(float(np.asarray(values.atVector(C))[2])),
        "yaw_sd_deg": math.sqrt(var_yaw),
        "misalignment_deg": math.degrees(float(np.asarray(values.atVector(D))[0])),
        "misalignment_sd_deg": math.sqrt(var_d),
        "correlation": cross / math.sqrt(var_yaw * var_d),
        "prior_sd_deg": {"yaw": sigma_yaw, "misalignment": sigma_d},
        "sonar_yaw_prior": isam.get("sonar_yaw_prior", "body"),
        "data_information_deg-2": info.tolist(),
        # (yaw - delta) / sqrt(2) and (yaw + delta) / sqrt(2): sd of the difference itself is
        # sqrt(2) times the first
        "data_sd_difference_deg": math.sqrt(2.0) / math.sqrt(i_diff) if i_diff > 0 else math.inf,
        "data_sd_sum_deg": math.sqrt(2.0) / math.sqrt(i_sum) if i_sum > 0 else math.inf,
    }


def rigid_rotation(run: Path) -> dict[str, float]:
    """The rotation (deg) of the rigid fit of each trajectory of ``run`` onto its ``gps.tum``
    over the sonar span (GPS as a ruler only)."""
    gps_path = run / "gps.tum"
    if not gps_path.is_file():
        return {}
    gps = read_tum(gps_path)
    metrics = json.loads((run / "metrics.json").read_text())
    span = metrics.get("sonar_span_s")
    out = {}
    for tum in sorted(run.glob("*.tum")):
        if tum.name == "gps.tum":
            continue
        est = read_tum(tum)
        t0, t1 = est.span_s
        if span is not None:
            t0, t1 = max(t0, span[0]), min(t1, span[1])
        inside = (gps.t_s >= t0) & (gps.t_s <= t1)
        a = est.poses(gps.t_s[inside])[:, :2]
        b = gps.poses(gps.t_s[inside])[:, :2]
        r, _, _ = umeyama_alignment(a.T, b.T, False)
        out[tum.stem] = math.degrees(math.atan2(r[1, 0], r[0, 0]))
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("runs", nargs="+", type=Path)
    ap.add_argument("--out", type=Path, default=None)
    args = ap.parse_args(argv)
    rows = []
    for run in args.runs:
        row = {
            "run": str(run),
            "joint": joint_information(run),
            "rigid_fit_rotation_deg": rigid_rotation(run),
        }
        j = row["joint"]
        text = f"{run}:"
        if j:
            text += (
                f" yaw {j['yaw_deg']:.3f} +- {j['yaw_sd_deg']:.3f}, misalignment"
                f" {j['misalignment_deg']:+.3f} +- {j['misalignment_sd_deg']:.3f} deg, corr"
                f" {j['correlation']:+.3f}; the data alone: sd of (yaw - delta)"
                f" {j['data_sd_difference_deg']:.3f} deg, of (yaw + delta)"
                f" {j['data_sd_sum_deg']:.3g} deg;"
            )
        text += " rigid fit onto GPS (ruler): " + ", ".join(
            f"{k} {v:+.2f} deg" for k, v in row["rigid_fit_rotation_deg"].items()
        )
        print(text, flush=True)
        rows.append(row)
    write_result({"benchmark": "calibration_gauge", "runs": rows}, args.out)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
