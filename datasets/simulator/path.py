"""True vehicle motion: body poses ``wTb`` sampled in time, with body velocities and yaw rates.

The body frame is x forward, y left; yaw is counter-clockwise from East (world frame local
East-North). Paths are polylines with circular fillets of a fixed turn radius, followed at a
slowly varying speed; the heading is the path tangent plus a slow "crab" angle (sideslip), so the
body velocity has a lateral component, as a real vehicle's does.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt

from sonarslam.datasets.simulator.world import World, clearance_m, inside
from sonarslam.features.geometry import FloatArray, interpolate_poses, wrap_angle

__all__ = [
    "T0_S",
    "TrueMotion",
    "stationary",
    "waypoint_path",
    "survey",
    "free_path",
    "route_samples",
]

#: Default start time of simulated runs (Unix s).
T0_S = 1.7e9


@dataclass(frozen=True, eq=False)
class TrueMotion:
    """True body motion sampled at a fixed rate; also a ``features.pose_source.PoseSource``.

    Attributes
    ----------
    t_s : ndarray, shape (N,)
        Sample times (Unix s), increasing.
    wTb : ndarray, shape (N, 3)
        Body poses ``(x_m, y_m, yaw_rad)`` in the world; yaw in ``[-pi, pi)``.
    v_body_mps : ndarray, shape (N, 2)
        Velocity over ground of the body origin in the body frame (m/s).
    yaw_rate_rad_per_s : ndarray, shape (N,)
        Yaw rate, counter-clockwise (rad/s).
    """

    t_s: FloatArray = field(repr=False)
    wTb: FloatArray = field(repr=False)
    v_body_mps: FloatArray = field(repr=False)
    yaw_rate_rad_per_s: FloatArray = field(repr=False)

    def poses(self, t_s: npt.ArrayLike) -> FloatArray:
        """Body poses at times ``t_s``, shape ``(M, 3)``, linearly interpolated (yaw on its arc)."""
        return interpolate_poses(t_s, self.t_s, self.wTb)

    def covariance(self, t_s: float) -> None:
        """The truth has no uncertainty."""
        return None

    def velocity_body_mps(self, t_s: npt.ArrayLike) -> FloatArray:
        """Body velocity at times ``t_s``, shape ``(M, 2)`` (m/s)."""
        tq = np.atleast_1d(np.asarray(t_s, dtype=np.float64))
        return np.stack([np.interp(tq, self.t_s, self.v_body_mps[:, i]) for i in (0, 1)], axis=-1)

    def yaw_rate_at(self, t_s: npt.ArrayLike) -> FloatArray:
        """Yaw rate at times ``t_s``, shape ``(M,)`` (rad/s, counter-clockwise)."""
        tq = np.atleast_1d(np.asarray(t_s, dtype=np.float64))
        return np.asarray(np.interp(tq, self.t_s, self.yaw_rate_rad_per_s))

    @property
    def duration_s(self) -> float:
        return float(self.t_s[-1] - self.t_s[0])


def _sample_times(duration_s: float, rate_hz: float, t0_s: float) -> FloatArray:
    if duration_s <= 0.0 or rate_hz <= 0.0:
        raise ValueError(f"duration_s and rate_hz must be positive, got {duration_s}, {rate_hz}")
    n = int(np.floor(duration_s * rate_hz + 1e-9)) + 1
    return t0_s + np.arange(n, dtype=np.float64) / rate_hz


def stationary(
    wTb: npt.ArrayLike, duration_s: float, rate_hz: float = 50.0, t0_s: float = T0_S
) -> TrueMotion:
    """A vehicle that does not move.

    Parameters
    ----------
    wTb : array_like, shape (3,)
        The body pose ``(x_m, y_m, yaw_rad)``.
    duration_s, rate_hz, t0_s : float
        Length (s), sample rate (Hz) and start time (Unix s).

    Returns
    -------
    TrueMotion
    """
    t = _sample_times(duration_s, rate_hz, t0_s)
    pose = np.asarray(wTb, dtype=np.float64).copy()
    pose[2] = float(wrap_angle(pose[2]))
    return TrueMotion(
        t_s=t,
        wTb=np.tile(pose, (t.size, 1)),
        v_body_mps=np.zeros((t.size, 2)),
        yaw_rate_rad_per_s=np.zeros(t.size),
    )


def _primitives(waypoints: FloatArray, radius_m: float, closed: bool) -> dict[str, FloatArray]:
    """Lines and fillet arcs of a polyline: start arc length, length, start point and heading,
    curvature (1/m, signed, counter-clockwise positive)."""
    w = waypoints
    k = w.shape[0]
    n_legs = k if closed else k - 1
    legs = np.array([w[(i + 1) % k] - w[i] for i in range(n_legs)])
    lengths = np.linalg.norm(legs, axis=1)
    if np.any(lengths <= 0.0):
        raise ValueError("waypoints must not repeat")
    dirs = legs / lengths[:, None]
    heading = np.arctan2(dirs[:, 1], dirs[:, 0])
    # turn at the end of leg i (into leg i+1); none at the ends of an open path
    n_turns = n_legs if closed else n_legs - 1
    turn = np.array([wrap_angle(heading[(i + 1) % n_legs] - heading[i]) for i in range(n_turns)])
    if np.any(np.abs(turn) > np.deg2rad(170.0)):
        raise ValueError("a turn of more than 170 deg cannot be filleted")
    tangent = radius_m * np.tan(np.abs(turn) / 2.0)
    cut_start = np.zeros(n_legs)
    cut_end = np.zeros(n_legs)
    cut_end[:n_turns] = tangent
    if closed:
        cut_start = np.roll(tangent, 1)
    else:
        cut_start[1:] = tangent
    if np.any(cut_start + cut_end > lengths + 1e-9):
        raise ValueError(f"a leg is too short for turn radius {radius_m} m")
    rows: list[tuple[float, float, float, float, float]] = []  # length, x, y, heading, curvature
    for i in range(n_legs):
        p0 = w[i] + cut_start[i] * dirs[i]
        rows.append((lengths[i] - cut_start[i] - cut_end[i], p0[0], p0[1], heading[i], 0.0))
        if i < n_turns:
            q = w[(i + 1) % k] - tangent[i] * dirs[i]
            rows.append(
                (radius_m * abs(turn[i]), q[0], q[1], heading[i], np.sign(turn[i]) / radius_m)
            )
    table = np.array(rows, dtype=np.float64)
    return {
        "s0": np.concatenate([[0.0], np.cumsum(table[:, 0])[:-1]]),
        "length": table[:, 0],
        "p0": table[:, 1:3],
        "h0": table[:, 3],
        "kappa": table[:, 4],
    }


def _evaluate(
    prims: dict[str, FloatArray], s: FloatArray
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Position (N, 2), tangent heading (N,) and curvature (N,) at arc lengths ``s``."""
    i = np.clip(np.searchsorted(prims["s0"], s, side="right") - 1, 0, prims["s0"].size - 1)
    sigma = np.clip(s - prims["s0"][i], 0.0, prims["length"][i])
    k = prims["kappa"][i]
    h0 = prims["h0"][i]
    h = h0 + k * sigma
    straight = k == 0.0
    k_safe = np.where(straight, 1.0, k)
    dx = np.where(straight, sigma * np.cos(h0), (np.sin(h) - np.sin(h0)) / k_safe)
    dy = np.where(straight, sigma * np.sin(h0), -(np.cos(h) - np.cos(h0)) / k_safe)
    return prims["p0"][i] + np.stack([dx, dy], axis=-1), h, k


def route_samples(
    waypoints_m: npt.ArrayLike, turn_radius_m: float, step_m: float = 0.5
) -> tuple[FloatArray, float]:
    """Points every ``step_m`` along a closed route with its fillets, as
    :func:`waypoint_path` follows it.

    Parameters
    ----------
    waypoints_m : array_like, shape (K, 2)
        Corners of the closed route (world, m).
    turn_radius_m, step_m : float
        Fillet radius and spacing of the points (m).

    Returns
    -------
    points_m : ndarray, shape (P, 2)
    length_m : float
        Length of one lap (m).

    Raises
    ------
    ValueError
        If a leg is too short for the fillets of its corners, or a turn is beyond 170 deg.
    """
    prims = _primitives(np.asarray(waypoints_m, dtype=np.float64), turn_radius_m, closed=True)
    total_m = float(prims["s0"][-1] + prims["length"][-1])
    xy, _, _ = _evaluate(prims, np.arange(0.0, total_m, step_m))
    return xy, total_m


def waypoint_path(
    waypoints_m: npt.ArrayLike,
    duration_s: float,
    speed_mps: float = 0.4,
    turn_radius_m: float = 4.0,
    closed: bool = True,
    speed_variation_mps: float = 0.05,
    speed_period_s: float = 90.0,
    crab_amplitude_rad: float = float(np.deg2rad(4.0)),
    crab_period_s: float = 70.0,
    rate_hz: float = 50.0,
    t0_s: float = T0_S,
) -> TrueMotion:
    """Follow a polyline with circular fillets, analytically.

    Speed ``v(t) = speed + speed_variation sin(2 pi t / speed_period)``; heading
    ``yaw = tangent + crab_amplitude sin(2 pi t / crab_period)``; so the body velocity is
    ``v (cos c, -sin c)`` for crab angle ``c`` and the yaw rate ``kappa v + dc/dt``.

    Parameters
    ----------
    waypoints_m : array_like, shape (K, 2)
        Corners (world, m). A closed route is followed round and round; an open one ends at its
        last corner, where the vehicle stops.
    duration_s : float
        Length of the run (s).
    speed_mps, speed_variation_mps, speed_period_s : float
        Mean speed, its sinusoidal variation (m/s) and period (s).
    turn_radius_m : float
        Fillet radius at every corner (m).
    closed : bool
        Whether the route closes on itself.
    crab_amplitude_rad, crab_period_s : float
        Sideslip between heading and course (rad) and its period (s).
    rate_hz, t0_s : float
        Sample rate (Hz) and start time (Unix s).

    Returns
    -------
    TrueMotion
    """
    w = np.asarray(waypoints_m, dtype=np.float64)
    if w.ndim != 2 or w.shape[1] != 2 or w.shape[0] < 2:
        raise ValueError(f"waypoints_m must have shape (K >= 2, 2), got {w.shape}")
    if speed_variation_mps >= speed_mps:
        raise ValueError("speed_variation_mps must be below speed_mps")
    prims = _primitives(w, turn_radius_m, closed)
    total_m = float(prims["s0"][-1] + prims["length"][-1])
    t = _sample_times(duration_s, rate_hz, t0_s)
    tau = t - t0_s
    omega_v = 2.0 * np.pi / speed_period_s
    v = speed_mps + speed_variation_mps * np.sin(omega_v * tau)
    s = speed_mps * tau + speed_variation_mps / omega_v * (1.0 - np.cos(omega_v * tau))
    if closed:
        s = np.mod(s, total_m)
    else:
        v = np.where(s < total_m, v, 0.0)
        s = np.minimum(s, total_m)
    xy, course, kappa = _evaluate(prims, s)
    omega_c = 2.0 * np.pi / crab_period_s
    crab = crab_amplitude_rad * np.sin(omega_c * tau)
    crab_rate = crab_amplitude_rad * omega_c * np.cos(omega_c * tau)
    return TrueMotion(
        t_s=t,
        wTb=np.column_stack([xy, wrap_angle(course + crab)]),
        v_body_mps=np.column_stack([v * np.cos(crab), -v * np.sin(crab)]),
        yaw_rate_rad_per_s=kappa * v + crab_rate,
    )


def survey(
    world: World,
    duration_s: float,
    speed_mps: float = 0.45,
    rate_hz: float = 50.0,
    t0_s: float = T0_S,
) -> TrueMotion:
    """Follow the world's own closed survey route (lawnmower and racetrack), see :class:`World`.

    Parameters
    ----------
    world : World
        A world with a ``route_m`` (e.g. :func:`~sonarslam.datasets.simulator.world.harbour_world`).
    duration_s, speed_mps, rate_hz, t0_s : float
        Length (s), mean speed (m/s), sample rate (Hz), start time (Unix s).

    Returns
    -------
    TrueMotion
    """
    if world.route_m is None:
        raise ValueError(f"world {world.name!r} has no survey route; use free_path")
    return waypoint_path(
        world.route_m,
        duration_s,
        speed_mps=speed_mps,
        turn_radius_m=world.route_turn_radius_m,
        closed=True,
        rate_hz=rate_hz,
        t0_s=t0_s,
    )


def _segment_clear(world: World, a: FloatArray, b: FloatArray, margin_m: float) -> bool:
    n = max(int(np.ceil(np.linalg.norm(b - a) / 0.5)), 1) + 1
    pts = a + np.linspace(0.0, 1.0, n)[:, None] * (b - a)
    return bool(np.all(inside(world, pts)) and np.all(clearance_m(world, pts) >= margin_m))


def free_path(
    world: World,
    rng: np.random.Generator,
    duration_s: float,
    speed_mps: float = 0.4,
    turn_radius_m: float = 3.0,
    margin_m: float = 3.0,
    rate_hz: float = 50.0,
    t0_s: float = T0_S,
    max_tries: int = 1000,
) -> TrueMotion:
    """A smooth path through random waypoints, at least ``margin_m`` from every wall.

    Waypoints are drawn where the clearance is at least ``margin_m + turn_radius_m tan(60 deg)``,
    so that any fillet of a turn up to 120 deg stays clear; each leg is checked every 0.5 m.

    Parameters
    ----------
    world : World
    rng : numpy.random.Generator
        The only source of randomness.
    duration_s, speed_mps, turn_radius_m, margin_m, rate_hz, t0_s : float
        Length (s), mean speed (m/s), fillet radius (m), wall clearance (m), sample rate (Hz),
        start time (Unix s).
    max_tries : int
        Waypoint choices (including steps back out of dead ends) before giving up.

    Returns
    -------
    TrueMotion

    Raises
    ------
    RuntimeError
        If the world has no room for such a path.
    """
    max_turn = np.deg2rad(120.0)
    corner_clearance = margin_m + turn_radius_m * np.tan(max_turn / 2.0)
    min_leg = 2.0 * turn_radius_m * np.tan(max_turn / 2.0) + 1.0
    x0, y0, x1, y1 = world.bounds_m
    cand = np.column_stack([rng.uniform(x0, x1, 4000), rng.uniform(y0, y1, 4000)])
    cand = cand[inside(world, cand)]
    cand = cand[clearance_m(world, cand) >= corner_clearance]
    if cand.shape[0] < 2:
        raise RuntimeError(f"world {world.name!r} has no room for a free path")
    needed_m = (speed_mps + 0.05) * duration_s + 2.0 * min_leg
    banned = np.zeros(cand.shape[0], dtype=bool)  # dead ends found so far
    chain = [int(rng.integers(cand.shape[0]))]  # indices into cand
    headings: list[float] = []
    legs_m: list[float] = []
    tries = 0
    # a fillet of turn theta shortens the path by R (2 tan(theta / 2) - theta), most at max_turn
    loss_per_corner_m = turn_radius_m * (2.0 * np.tan(max_turn / 2.0) - max_turn)
    while sum(legs_m) - loss_per_corner_m * len(legs_m) < needed_m:
        tries += 1
        if tries > max_tries:
            raise RuntimeError(f"no free path found in world {world.name!r}")
        leg = cand - cand[chain[-1]]
        dist = np.hypot(leg[:, 0], leg[:, 1])
        ok = (dist >= min_leg) & (dist <= 80.0) & ~banned
        h = np.arctan2(leg[:, 1], leg[:, 0])
        if headings:
            ok &= np.abs(wrap_angle(h - headings[-1])) <= max_turn
        chosen = -1
        for j in rng.permutation(np.flatnonzero(ok))[:30]:
            if _segment_clear(world, cand[chain[-1]], cand[j], margin_m):
                chosen = int(j)
                break
        if chosen < 0:  # dead end: never come here again, step back
            banned[chain[-1]] = True
            if len(chain) > 1:
                chain.pop()
                headings.pop()
                legs_m.pop()
            elif np.all(banned):
                raise RuntimeError(f"no free path found in world {world.name!r}")
            else:
                chain[0] = int(rng.choice(np.flatnonzero(~banned)))
            continue
        chain.append(chosen)
        headings.append(float(h[chosen]))
        legs_m.append(float(dist[chosen]))
    points = cand[chain]
    return waypoint_path(
        points,
        duration_s,
        speed_mps=speed_mps,
        turn_radius_m=turn_radius_m,
        closed=False,
        rate_hz=rate_hz,
        t0_s=t0_s,
    )
