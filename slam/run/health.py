"""The hook between a closed loop and the health monitor (:mod:`sonarslam.slam.eval.health`).

Both back ends feed the monitor the same way, from what a run already logs: the causal
trajectory with its covariances (:class:`sonarslam.slam.run.closed_loop.ClosedLoopResult`), the landmark
layer's innovations and associations (:class:`sonarslam.slam.mapping.landmarks.LandmarkMap`, shared), the
final constants of :meth:`sonarslam.slam.backends.base.Backend.metrics` (``state_*``), and the logs a
back end keeps beyond those when it has them: ``heading_innovations`` (the EKF's AHRS updates)
and the scan constraints' pairs (iSAM2 with ``scans``). Dead reckoning from the same sensors
is the reference the estimate must stay near. Nothing here reads GPS; the simulator's truth,
on simulated data only, feeds the ``nees`` check.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from sonarslam.datasets.source import Dataset
from sonarslam.slam.eval.health import (
    HealthConfig,
    HealthInputs,
    HealthReport,
    NisStream,
    StateValue,
    assess,
)
from sonarslam.slam.eval.loops import OdometryCheck
from sonarslam.slam.eval.truth import truth_trajectory
from sonarslam.slam.model.motion import body_yaw
from sonarslam.slam.run.closed_loop import ClosedLoopResult
from sonarslam.slam.run.sources import (
    dead_reckoning_trajectory,
    dvl_body_velocities,
    mounting_yaw_said,
)

__all__ = ["nis_streams", "health_inputs", "monitor_run"]


def _scan_pairs(backend: Any) -> list[dict[str, Any]]:
    scans = getattr(backend, "scans", None)
    log = getattr(scans, "log", None)
    return list(getattr(log, "pairs", []))


def nis_streams(result: ClosedLoopResult) -> list[NisStream]:
    """The NIS a closed loop logged, per kind: ``line`` (the landmark layer's updates),
    ``heading`` (the EKF's AHRS updates), ``scan`` (iSAM2's kept scan revisits)."""
    backend = result.backend
    cfg = backend.config
    lm = backend.map
    gate = cfg.association.gate_probability
    streams = []
    if lm.innovations:
        t = np.array([v.t_s for v in lm.innovations])
        streams.append(NisStream("line", t, lm.nis(), 2, gate))
    heading = getattr(backend, "heading_innovations", None)
    if heading:
        h = np.asarray(heading, dtype=np.float64)
        streams.append(NisStream("heading", h[:, 0], h[:, 1] ** 2 / h[:, 2], 1))
    # the revisits kept: a registration that is no revisit of the same place (a wrong match) is
    # refused by the compatibility gate, which is why the kept ones are judged, as gated
    kept = [p for p in _scan_pairs(backend) if p.get("nis") is not None and p.get("accepted")]
    if kept:
        t = np.array([p["t_k"] for p in kept])
        nis = np.array([p["nis"] for p in kept])
        streams.append(
            NisStream("scan", t, nis, 3, getattr(cfg, "scan_compatibility_probability", None))
        )
    return streams


def health_inputs(
    dataset: Dataset, result: ClosedLoopResult, odometry: OdometryCheck | None = None
) -> HealthInputs:
    """What the monitor reads of a closed loop's run (module docstring), with the run's odometry
    check (:func:`sonarslam.slam.eval.loops.odometry_check`) when it has one."""
    backend = result.backend
    cfg = backend.config
    lm = backend.map
    t_end = float(result.trajectory.t_s[-1])
    streams = nis_streams(result)
    created: dict[int, float] = {}
    reobserved = []
    for t_s, _, j in lm.association_log:
        if j is None:
            continue
        if j in created:
            reobserved.append(t_s)
        else:
            created[j] = t_s
    for f, j in lm.seed_log:  # a landmark exists from its first (tentative) observation on
        created[j] = min(created.get(j, f.t), f.t)
    m = backend.metrics()
    t0 = float(result.trajectory.t_s[0])
    # the model in force: a walk the loop learned (learn_noise) is judged as told, at its largest
    walk_deg = max(
        cfg.noise.ahrs_bias_walk_deg_per_sqrt_s,
        float(m.get("noise_heading_walk_deg_per_sqrt_s_max", 0.0)),
    )
    walk = float(np.deg2rad(walk_deg))
    bias_sigma = float(np.deg2rad(cfg.noise.ahrs_bias_sigma_deg))
    states = []
    if "state_ahrs_bias_deg" in m:
        sigma = float(np.rad2deg(np.sqrt(bias_sigma**2 + walk**2 * (t_end - t0))))
        states.append(StateValue("AHRS bias", float(m["state_ahrs_bias_deg"]), sigma, "deg"))
    if "state_misalignment_deg" in m:
        states.append(
            StateValue(
                "DVL misalignment",
                float(m["state_misalignment_deg"]),
                cfg.misalignment_sigma_deg,
                "deg",
            )
        )
    if "state_dvl_scale" in m:
        scale_walk = float(m.get("noise_dvl_scale_walk_per_sqrt_s_max", 0.0))
        sigma = float(np.hypot(cfg.noise.dvl_scale_sigma, scale_walk * np.sqrt(t_end - t0)))
        states.append(StateValue("DVL scale", float(m["state_dvl_scale"]), sigma, ""))
    gyro_sigma = getattr(cfg, "gyro_bias_sigma_deg_per_s", None)
    if "state_gyro_bias_deg_per_s" in m and gyro_sigma is not None:
        states.append(
            StateValue("gyro bias", float(m["state_gyro_bias_deg_per_s"]), gyro_sigma, "deg/s")
        )
    c = dataset.config
    att = dataset.attitude
    return HealthInputs(
        trajectory=result.trajectory,
        reference=dead_reckoning_trajectory(dataset),
        ahrs_t_s=att.t,
        ahrs_yaw_rad=body_yaw(att.yaw_rad, c.ahrs_mounting, c.ahrs_deviation_rad),
        ahrs_bias_sigma_rad=bias_sigma,
        ahrs_bias_walk_rad_per_sqrt_s=walk,
        nis=streams,
        landmark_created_s=np.array(sorted(created.values())),
        reobserved_s=np.array(reobserved),
        states=states,
        truth=truth_trajectory(dataset) if dataset.truth is not None else None,
        # the beams the extractor saw: none when the back end takes no lines (scans only)
        n_beams=int(result.counts.get("beams", 0)) if "lines" in cfg.constraint_kinds else 0,
        n_lines=len(result.features),
        travel_body_mps=dvl_body_velocities(dataset),
        odometry=odometry,
        mountings_said=", ".join(
            mounting_yaw_said(name, m)
            for name, m in (("sonar", c.sonar_mounting), ("dvl", c.dvl_mounting))
        ),
    )


def monitor_run(
    dataset: Dataset,
    result: ClosedLoopResult,
    config: HealthConfig | None = None,
    odometry: OdometryCheck | None = None,
) -> HealthReport:
    """:func:`sonarslam.slam.eval.health.assess` on a closed loop's run (and its odometry check,
    when it has one)."""
    return assess(health_inputs(dataset, result, odometry), config)
