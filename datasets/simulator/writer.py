"""Writing a simulated run in the marina layout, with its ground truth.

Files written in ``out_dir`` (prefix ``sim_<kind>_<seed>``):

=============================  =============================================================
``<prefix>_IS.log``            raw beams, :func:`sonarslam.datasets.islog.write_is_log`
``<prefix>_IS_timestamps.log`` ``logTime sensorTime`` per beam (ms since midnight UTC), no header
``<prefix>_SETUP.log``         ``range_m bin_size_m step_rad``
``<prefix>_DVL.log``           32 columns in the real DVL log's order, velocities in cm/s
``<prefix>_MTi.log``           10 columns: logTime, roll, pitch, yaw (deg), rates (rad/s), acc
``<prefix>_DGPS.log``          10 columns: logTime, lat, lon (ddmm.mmmmmm), status, ...
``sonarslam.toml``             :func:`sonarslam.datasets.config.dump_dataset_config` of the scenario
``truth.json``                 true poses, walls, mountings, geodetic origin, seed (see below)
=============================  =============================================================

The DVL, MTi and DGPS logs have ``%`` headers and CRLF line ends, like the real ones.

``truth.json`` (schema ``sonarslam.simulator.truth/1``): world coordinates are local East-North
metres whose origin is the geodetic origin; the project's readers put their origin at the first
GPS fix instead, so ``reader_local = world - first_fix_enu_m`` (to a few 1e-5 of the distance
from the first fix: the two tangent planes differ by that much). Keys: ``schema, kind, seed,
prefix, frames, scenario, geodetic_origin, first_fix_t, first_fix_enu_m, head, mountings,
noise, walls_m, route_m, body_poses {columns, rate_hz, rows}, beams {columns, rows},
dvl_dropouts_s``; NaN is written as null. A scenario with systematic sensor errors (the ``drift``
kind) adds ``errors`` (:class:`~sonarslam.datasets.simulator.sensors.DriftErrors`: ``dvl_scale_factor,
dvl_bias_mps, ahrs_heading_walk_deg_per_sqrt_s, echo_range_offset_m``) and, with a heading walk,
``ahrs_heading_walk {columns: [t, walk_deg], rate_hz, rows}``: the walk in the logged MTi heading
(clockwise, deg) at every tenth AHRS sample. A drawn world (the ``drawn`` kind) adds ``walls
{echo_gain, band_m, curve, material}`` (one value per row of ``walls_m``: the echo strength
factor, the band thickness in m, the curved stretch a wall is a facet of or -1, its material)
and ``layout`` (:attr:`~sonarslam.datasets.simulator.world.World.layout`: basins, channels, features, the
lap).
"""

from __future__ import annotations

import json
import math
from dataclasses import asdict
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import numpy as np
import pymap3d

from sonarslam.datasets.config import dump_dataset_config
from sonarslam.datasets.geodesy import ddmm_to_degrees, degrees_to_ddmm
from sonarslam.datasets.islog import write_is_log
from sonarslam.datasets.simulator.scenario import Simulation, make_scenario, simulate_records
from sonarslam.features.geometry import FloatArray
from sonarslam.sonar.beam import Mounting

__all__ = [
    "TRUTH_SCHEMA",
    "first_fix_enu_m",
    "write_dataset",
    "drop_gps",
    "simulate",
]

TRUTH_SCHEMA = "sonarslam.simulator.truth/1"
_CRLF = "\r\n"


def _write_lines(path: Path, lines: list[str], newline: str) -> None:
    path.write_bytes((newline.join(lines) + newline).encode("ascii"))


def _write_timestamps(path: Path, sim: Simulation) -> None:
    lines = [f"{b.t:.3f} {int(round((b.t % 86400.0) * 1000.0))}" for b in sim.beams]
    _write_lines(path, lines, "\n")


def _write_setup(path: Path, sim: Simulation) -> None:
    h = sim.scenario.head
    _write_lines(path, [f"{h.range_max_m:.10g} {h.bin_size_m:.10g} {h.step_rad:.14f}"], "\n")


def _write_dvl(path: Path, sim: Simulation) -> None:
    d = sim.dvl
    header = [
        "% ---------------------------------------",
        "% Data columns: ",
        "% logTime (s), year, month, day, hour, minute, second, waterVelX (cm/s), "
        "waterVelY (cm/s), waterVelZ (cm/s), waterVelStatus, bottomVelX (cm/s), "
        "bottomVelY (cm/s), bottomVelZ (cm/s), bottomVelStatus, rangeBottom1, rangeBottom2, "
        "rangeBottom3, amplitude1, amplitude2, amplitude3, percentGoodPings, heading, pitch, "
        "roll, temperature, pressure, powerLevel, slosv, elosv, distanceTravelX, distanceTravelY",
        "% simulated by sonarslam: velocities in the DVL frame (x, y, z up); no water current, so"
        " waterVel = bottomVel; heading = DVL compass, clockwise from North (deg);"
        " distanceTravel = displacement since the previous row (m)",
        "% ---------------------------------------",
        "",
    ]
    v_cm = np.where(d.valid[:, None], d.v_dvl_mps * 100.0, 0.0)
    dt = np.diff(d.t_s, prepend=d.t_s[0])
    travel = v_cm[:, :2] / 100.0 * dt[:, None]
    compass = np.mod(np.round(d.compass_deg, 2), 360.0)  # never "360.00"
    lines = list(header)
    for i in range(d.t_s.size):
        t = float(d.t_s[i])
        ts = datetime.fromtimestamp(t, tz=UTC)
        vx, vy, vz = v_cm[i]
        wx, wy, wz = d.v_dvl_mps[i] * 100.0
        ok = int(d.valid[i])
        rb = d.altitude_m[i] if ok else 0.0
        lines.append(
            f"{t:.3f}\t\t{ts.year} {ts.month} {ts.day} {ts.hour} {ts.minute} {ts.second} "
            f"{wx:.2f} {wy:.2f} {wz:.2f} 1 {vx:.2f} {vy:.2f} {vz:.2f} {ok} "
            f"{rb:.2f} {rb:.2f} {rb:.2f} 140.00 140.00 140.00 {100 if ok else 0} "
            f"{compass[i]:.2f} -0.50 1.60 14.27 1488.00 12.80 0.50 1.50 "
            f"{travel[i, 0]:.2f} {travel[i, 1]:.2f}"
        )
    _write_lines(path, lines, _CRLF)


def _write_mti(path: Path, sim: Simulation) -> None:
    a = sim.ahrs
    header = [
        "% ---------------------------------------",
        "% Data columns: ",
        "% logTime (s), roll (deg), pitch (deg), yaw (deg, heading clockwise from North, +-180), "
        "rate_x, rate_y, rate_z (rad/s), acc_x, acc_y, acc_z (m/s^2)",
        "% simulated by sonarslam: MTi axes x forward, y right, z down (rate_z > 0 turning "
        "clockwise, acc_z = -g at rest)",
        "% ---------------------------------------",
        "",
    ]
    lines = list(header)
    for i in range(a.t_s.size):
        r, q = a.rate_rad_per_s[i], a.acc_mps2[i]
        lines.append(
            f"{a.t_s[i]:.3f}\t\t{a.roll_deg[i]:.4f}\t{a.pitch_deg[i]:.4f}\t{a.heading_deg[i]:.4f}"
            f"\t\t{r[0]:.6f}\t{r[1]:.6f}\t{r[2]:.6f}\t\t{q[0]:.5f}\t{q[1]:.5f}\t{q[2]:.5f}\t\t"
        )
    _write_lines(path, lines, _CRLF)


def _gps_ddmm(sim: Simulation) -> tuple[FloatArray, FloatArray]:
    """Latitude and longitude as written (ddmm with 6 decimals of minutes)."""
    lat = np.round(degrees_to_ddmm(sim.gps.lat_deg), 6)
    lon = np.round(degrees_to_ddmm(sim.gps.lon_deg), 6)
    return lat, lon


def _write_dgps(path: Path, sim: Simulation) -> None:
    g = sim.gps
    header = [
        "% " + "-" * 100,
        "% Data columns: ",
        "% logTime (s), latitude (deg|min.fract_min), longitude (deg|min.fract_min), "
        "status (1=GPS 2=DGPS), altitude (m), geoideAltitude (m), trueCourse(M-:), "
        "magneticCourse(M-:), speed(kts), speed(Km/h)",
        "% " + "-" * 100,
        "",
    ]
    lat, lon = _gps_ddmm(sim)
    lines = list(header)
    for i in range(g.t_s.size):
        course = float(np.mod(np.round(g.course_deg[i], 1), 360.0))
        speed = float(g.speed_mps[i])
        lines.append(
            f"{g.t_s[i]:.3f}\t{lat[i]:.6f}\t{lon[i]:.6f}\t1\t0.0\t51.8\t{course:.1f}\t"
            f"{(course - 1.0) % 360.0:.1f}\t{speed * 3600.0 / 1852.0:.2f}\t{speed * 3.6:.2f}"
        )
    _write_lines(path, lines, _CRLF)


def _clean(x: Any) -> Any:
    """JSON-safe: NaN and infinities become None, numpy numbers plain floats."""
    if isinstance(x, dict):
        return {k: _clean(v) for k, v in x.items()}
    if isinstance(x, list | tuple):
        return [_clean(v) for v in x]
    if isinstance(x, np.ndarray):
        return _clean(x.tolist())
    if isinstance(x, float | np.floating):
        return float(x) if math.isfinite(x) else None
    if isinstance(x, np.integer):
        return int(x)
    return x


def _mounting(m: Mounting) -> dict[str, Any]:
    return {"x_m": m.x_m, "y_m": m.y_m, "yaw_rad": m.yaw_rad, "source": m.source}


def first_fix_enu_m(sim: Simulation) -> FloatArray:
    """World East-North (m) of the first GPS fix as written in the DGPS log."""
    lat, lon = _gps_ddmm(sim)
    o = sim.scenario.origin
    e, n, _ = pymap3d.geodetic2enu(
        float(ddmm_to_degrees(lat[0])),
        float(ddmm_to_degrees(lon[0])),
        0.0,
        o.lat_deg,
        o.lon_deg,
        o.h_m,
    )
    return np.array([float(e), float(n)])


def _truth(sim: Simulation) -> dict[str, Any]:
    s = sim.scenario
    tr = sim.trajectory
    step = max(int(round(s.path_rate_hz / 10.0)), 1)
    poses = np.column_stack([tr.t_s, tr.wTb])[::step]
    beams = np.column_stack(
        [
            [b.t for b in sim.beams],
            [b.transducer_angle_rad for b in sim.beams],
            sim.beam_axis_range_m,
            sim.beam_axis_incidence_rad,
        ]
    )
    h = s.head
    truth: dict[str, Any] = {
        "schema": TRUTH_SCHEMA,
        "kind": s.kind,
        "seed": s.seed,
        "prefix": s.prefix,
        "frames": {
            "world": "local East-North (x east, y north, m), origin at geodetic_origin",
            "body": "x forward, y left; yaw counter-clockwise from East (rad)",
            "reader_local": "the readers' frame, origin at the first GPS fix: "
            "reader_local = world - first_fix_enu_m",
            "sonar_bearing": "bearing in the sonar frame = angle_sense * transducer angle; "
            "wTs = compose(wTb, bTs)",
        },
        "scenario": {
            "duration_s": s.duration_s,
            "t0_s": s.t0_s,
            "beam_rate_hz": s.beam_rate_hz,
            "sector_rad": s.sector_rad,
            "speed_mps": s.speed_mps,
            "path_rate_hz": s.path_rate_hz,
            "dvl_rate_hz": s.dvl_rate_hz,
            "ahrs_rate_hz": s.ahrs_rate_hz,
            "gps_rate_hz": s.gps_rate_hz,
            "echo": asdict(s.echo),
        },
        "geodetic_origin": asdict(s.origin),
        "first_fix_t": float(sim.gps.t_s[0]),
        "first_fix_enu_m": first_fix_enu_m(sim),
        "head": {
            "n_bins": h.n_bins,
            "bin_size_m": h.bin_size_m,
            "step_rad": h.step_rad,
            "beam_width_rad": h.beam_width_rad,
            "angle_sense": h.angle_sense,
            "range_max_m": h.range_max_m,
        },
        "mountings": {
            "sonar": _mounting(s.sonar_mounting),
            "dvl": _mounting(s.dvl_mounting),
            "ahrs": _mounting(s.ahrs_mounting),
        },
        "noise": asdict(s.noise),
        "walls_m": sim.world.walls_m,
        "route_m": sim.world.route_m,
        "body_poses": {
            "columns": ["t", "x_m", "y_m", "yaw_rad"],
            "rate_hz": s.path_rate_hz / step,
            "rows": poses,
        },
        "beams": {
            "columns": ["t", "transducer_angle_rad", "axis_range_m", "axis_incidence_rad"],
            "rows": beams,
        },
        "dvl_dropouts_s": sim.dvl.dropouts_s,
    }
    w = sim.world
    if w.wall_gain is not None:  # drawn worlds: each wall's echo, and what the world is made of
        truth["walls"] = {
            "echo_gain": w.wall_gain,
            "band_m": w.wall_band_m,
            "curve": w.wall_curve,
            "material": list(w.wall_material or ()),
        }
    if w.layout is not None:
        truth["layout"] = w.layout
    if s.errors is not None:  # absent for the kinds without: their truth.json is unchanged
        truth["errors"] = asdict(s.errors)
    walk = sim.ahrs.heading_walk_deg
    if walk is not None:
        every = max(int(round(s.ahrs_rate_hz)), 1)
        truth["ahrs_heading_walk"] = {
            "columns": ["t", "walk_deg"],
            "rate_hz": s.ahrs_rate_hz / every,
            "rows": np.column_stack([sim.ahrs.t_s, walk])[::every],
        }
    return _clean(truth)


def write_dataset(sim: Simulation, out_dir: str | Path) -> Path:
    """Write a simulated run in the marina layout (see the module docstring).

    Parameters
    ----------
    sim : Simulation
    out_dir : str or Path
        Created if missing; existing files of the same names are overwritten.

    Returns
    -------
    Path
        ``out_dir``.
    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    prefix = sim.scenario.prefix
    write_is_log(out / f"{prefix}_IS.log", sim.beams)
    _write_timestamps(out / f"{prefix}_IS_timestamps.log", sim)
    _write_setup(out / f"{prefix}_SETUP.log", sim)
    _write_dvl(out / f"{prefix}_DVL.log", sim)
    _write_mti(out / f"{prefix}_MTi.log", sim)
    _write_dgps(out / f"{prefix}_DGPS.log", sim)
    (out / "sonarslam.toml").write_text(
        dump_dataset_config(sim.scenario.dataset_config()), encoding="utf-8"
    )
    (out / "truth.json").write_text(
        json.dumps(_truth(sim), allow_nan=False) + "\n", encoding="utf-8"
    )
    return out


def drop_gps(layout: str | Path) -> None:
    """Remove a simulated run's GPS (its ``*_DGPS.log``): a run without GPS, ``truth.json``
    kept (``sonarslam simulate --no-gps``)."""
    for log in Path(layout).glob("*_DGPS.log"):
        log.unlink()


def simulate(kind: str, seed: int, out_dir: str | Path, duration_s: float | None = None) -> Path:
    """Simulate the default scenario of ``kind`` and write it to ``out_dir``.

    Parameters
    ----------
    kind : {"pool", "harbour", "random", "drift", "drawn"}
    seed : int
    out_dir : str or Path
    duration_s : float, optional
        Overrides the scenario's default length (s).

    Returns
    -------
    Path
        ``out_dir``, holding ``sim_<kind>_<seed>_*.log``, ``sonarslam.toml`` and ``truth.json``.
    """
    return write_dataset(simulate_records(make_scenario(kind, seed, duration_s)), out_dir)
